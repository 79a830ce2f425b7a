"""Finding the ArduPilot Rover SITL binary: ``--firmware PATH``, else ``RETURNLINK_ARDUROVER``, else ``ardurover``
on PATH (docs/architecture.md §10). A missing or unusable binary is a usage error (exit 2) that names all three ways and
how to build one, because a user who asked for the real firmware must not silently get something else."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

ENV = "RETURNLINK_ARDUROVER"
BUILD = ("git clone --recurse-submodules https://github.com/ArduPilot/ardupilot && cd ardupilot && "
         "./waf configure --board sitl && ./waf rover   # -> build/sitl/bin/ardurover")


class FirmwareNotFound(Exception):
    """The firmware binary could not be found or cannot be run; the message says where we looked."""


def _usable(path: Path) -> bool:
    return path.is_file() and os.access(path, os.X_OK)


def find_firmware(option: str | None = None, environ: dict[str, str] | None = None) -> Path:
    """The binary to run: the first of the three ways that is given. A way that is given but unusable is an error
    naming it (a typo in --firmware must not fall back to some other binary on PATH)."""
    env = os.environ if environ is None else environ
    if option:
        p = Path(option).expanduser()
        if not _usable(p):
            raise FirmwareNotFound(f"--firmware {option}: not an executable file")
        return p.resolve()
    if env.get(ENV):
        p = Path(env[ENV]).expanduser()
        if not _usable(p):
            raise FirmwareNotFound(f"{ENV}={env[ENV]}: not an executable file")
        return p.resolve()
    found = shutil.which("ardurover", path=env.get("PATH"))
    if found:
        return Path(found).resolve()
    raise FirmwareNotFound(
        "no ArduPilot Rover SITL binary: give --firmware PATH, set RETURNLINK_ARDUROVER=PATH, or put 'ardurover' "
        f"on PATH. Any ArduPilot 4.5+ Rover SITL works; to build one: {BUILD}")
