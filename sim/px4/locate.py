"""Finding PX4: ``--px4 DIR``, else ``RETURNLINK_PX4``, else none (docs/architecture.md §10.1).

A PX4 here is a directory, not a binary: ``bin/px4`` runs only with its own start-up tree ``etc/`` (the ROMFS: rcS,
the airframes, among them 1069_hil_rover_differential) beside it. There is no PATH fallback: a ``px4`` on PATH
says nothing about where its ``etc/`` is. A way that is given but unusable is an error naming it, never a fallback
to the other way, because a user who asked for one PX4 must not silently get another.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV = "RETURNLINK_PX4"
SHARED = "../shared/px4/"  # where the project keeps a ready PX4 rover SITL, and its README with how it was built
AIRFRAME = "1069_hil_rover_differential"  # the airframe the bridge drives: its two outputs are the wheels


class PX4NotFound(Exception):
    """No usable PX4 directory was given; the message says which ways there are and what was wrong."""


def check_px4_dir(path: Path) -> Path:
    """``path`` resolved, if it holds an executable ``bin/px4`` and an ``etc/`` with the rover airframe; else
    PX4NotFound saying what is missing."""
    p = Path(path).expanduser()
    binary = p / "bin" / "px4"
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        raise PX4NotFound(f"{p}: no executable bin/px4")
    if not (p / "etc" / "init.d-posix" / "rcS").is_file():
        raise PX4NotFound(f"{p}: no etc/ start-up tree (etc/init.d-posix/rcS) beside bin/px4")
    if not (p / "etc" / "init.d-posix" / "airframes" / AIRFRAME).is_file():
        raise PX4NotFound(f"{p}: etc/ has no airframe {AIRFRAME}, which the bridge's wheel mapping needs")
    return p.resolve()


def find_px4(option: str | None = None, environ: dict[str, str] | None = None) -> Path:
    """The PX4 directory to run: ``--px4 DIR`` if given, else $RETURNLINK_PX4; neither: PX4NotFound naming both
    ways and the README of the ready build (exit 2 at the command line)."""
    env = os.environ if environ is None else environ
    if option:
        try:
            return check_px4_dir(Path(option))
        except PX4NotFound as e:
            raise PX4NotFound(f"--px4 {option}: {e}") from None
    if env.get(ENV):
        try:
            return check_px4_dir(Path(env[ENV]))
        except PX4NotFound as e:
            raise PX4NotFound(f"{ENV}={env[ENV]}: {e}") from None
    raise PX4NotFound(
        f"no PX4: give --px4 DIR or set {ENV}=DIR, a directory holding bin/px4 and etc/ (a PX4 rover SITL build "
        f"with airframe {AIRFRAME}). A ready one is in {SHARED}; its README.md says how it was built and what "
        "was measured with it.")
