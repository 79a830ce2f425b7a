"""The returnlink MAVLink dialect: the XML contract and its generated pymavlink module.

The XML is the contract; the Python module is generated from it with pymavlink's own mavgen, so it can never
drift from the XML. The generated file is installed into pymavlink's dialect package when that is writable, which
makes ``mavutil.mavlink_connection(..., dialect="returnlink")`` and ``mavproxy.py --dialect returnlink`` work in any
program of the same environment; otherwise it is cached per user and registered in ``sys.modules`` for this process.
A header line records the XML's hash, so an edited XML regenerates on next use.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import importlib.util
import io
import os
import shutil
import sys
import tempfile
from pathlib import Path
from types import ModuleType

os.environ.setdefault("MAVLINK20", "1")

XML_PATH = Path(__file__).with_name("returnlink.xml")
MODULE_NAME = "pymavlink.dialects.v20.returnlink"
_HASH_TAG = "# returnlink-xml-sha256: "


def xml_text() -> str:
    return XML_PATH.read_text(encoding="utf-8")


def xml_hash() -> str:
    return hashlib.sha256(XML_PATH.read_bytes()).hexdigest()


def _pymavlink_v20_dir() -> Path:
    import pymavlink.dialects.v20 as v20

    return Path(v20.__file__).parent


def _user_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "returnlink"


def generate_source() -> str:
    """Run mavgen on the XML (resolving common.xml from pymavlink's bundled definitions)."""
    from pymavlink.generator import mavgen

    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        for inc in ("common.xml", "standard.xml", "minimal.xml"):
            shutil.copy(_pymavlink_v20_dir() / inc, tmpdir / inc)
        xml = tmpdir / "returnlink.xml"
        shutil.copy(XML_PATH, xml)
        opts = mavgen.Opts(
            str(tmpdir / "returnlink"), wire_protocol="2.0", language="Python3", validate=True,
            strict_units=False,
        )
        with contextlib.redirect_stdout(io.StringIO()):
            ok = mavgen.mavgen(opts, [str(xml)])
        if not ok:
            raise RuntimeError(f"mavgen rejected {XML_PATH}")
        src = (tmpdir / "returnlink.py").read_text(encoding="utf-8")
    return f"{_HASH_TAG}{xml_hash()}\n{src}"


def _is_current(path: Path) -> bool:
    try:
        with path.open(encoding="utf-8") as f:
            return f.readline().strip() == f"{_HASH_TAG}{xml_hash()}"
    except OSError:
        return False


def install() -> Path:
    """Generate the module if needed and place it where pymavlink looks for dialects. Returns its path."""
    target = _pymavlink_v20_dir() / "returnlink.py"
    if _is_current(target):
        return target
    src = generate_source()
    try:
        target.write_text(src, encoding="utf-8")
        shutil.copy(XML_PATH, target.with_suffix(".xml"))
        importlib.invalidate_caches()
        return target
    except OSError:
        cache = _user_cache_dir() / "returnlink.py"
        cache.parent.mkdir(parents=True, exist_ok=True)
        cache.write_text(src, encoding="utf-8")
        return cache


_module: ModuleType | None = None


def load() -> ModuleType:
    """The generated dialect module, registered as ``pymavlink.dialects.v20.returnlink``."""
    global _module
    if _module is not None:
        return _module
    path = install()
    if MODULE_NAME in sys.modules and getattr(sys.modules[MODULE_NAME], "__file__", None) == str(path):
        _module = sys.modules[MODULE_NAME]
        return _module
    spec = importlib.util.spec_from_file_location(MODULE_NAME, path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[MODULE_NAME] = mod
    spec.loader.exec_module(mod)
    import pymavlink.dialects.v20 as v20

    v20.returnlink = mod  # type: ignore[attr-defined]
    _module = mod
    return mod
