"""vehicle/frozen.py: ``evolve`` makes the value ``dataclasses.replace`` makes, and refuses a field that is not one."""

from __future__ import annotations

from dataclasses import replace

import pytest

from vehicle.frozen import evolve
from vehicle.lease import LeaseBook
from vehicle.link_watch import Delivery, LinkWatch


def test_evolve_is_replace():
    w = LinkWatch().heard(1.0, 7).heard(1.1, 8)
    assert evolve(w, lost=True, last_heard=2.0) == replace(w, lost=True, last_heard=2.0)
    d = Delivery(((1.0, 3),), 3, 1.0, 0)
    assert evolve(d, last_t=1.5) == replace(d, last_t=1.5)
    b = LeaseBook()
    e = evolve(b, link=w)
    assert e == replace(b, link=w) and e is not b and b.link == LinkWatch()  # the original is untouched


def test_evolve_keeps_the_value_frozen_and_refuses_unknown_fields():
    w = evolve(LinkWatch(), lost=True)
    with pytest.raises(AttributeError):
        w.lost = False  # type: ignore[misc]
    with pytest.raises(TypeError, match="no field 'lots'"):
        evolve(w, lots=True)


@pytest.mark.parametrize("kind", [LeaseBook])
def test_the_values_evolve_copies_check_nothing_it_would_skip(kind):
    """``evolve`` copies the instance dictionary instead of calling ``__init__``: right only while the value has
    no ``__post_init__`` check, no ``init=False`` field and no slots. A value that gains one must go back to
    ``dataclasses.replace``; this says so before a check is silently skipped."""
    import dataclasses

    assert dataclasses.is_dataclass(kind) and kind.__dataclass_params__.frozen
    assert not hasattr(kind, "__post_init__")
    assert all(f.init for f in dataclasses.fields(kind))
    assert not hasattr(kind, "__slots__")
