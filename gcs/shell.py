"""``returnlink gcs shell``: one long-lived station at a prompt, or reading commands from a pipe or file.

A one-shot ``returnlink gcs COMMAND`` is a short session: between two commands the station is silent, and a
vehicle with ``LNK_TIMEOUT`` of a few seconds rightly treats that silence as a lost link and starts its return
chain. The shell keeps one link open for as long as the operator works: a background thread pumps the station
(its 1 Hz heartbeat, a running teleop stream, retries) while the prompt waits, and prints lease events and
STATUSTEXTs as they arrive. Commands (the table in ``gcs/commands.py``) come from a terminal (history and
completion through ``readline``) or from a pipe or file for scripts, where the first refused command ends the
shell with its exit code.
"""

from __future__ import annotations

import argparse
import cmd
import contextlib
import shlex
import sys
import threading
import time
from collections.abc import Callable
from typing import TextIO

from gcs.client import Client
from gcs.commands import COMMANDS, Context, UsageError, add_commands, execute, find

IDLE_PUMP = 0.05  # s between background exchanges while the prompt waits


# ----- the shell --------------------------------------------------------------------------------------------------
class _LineParser(argparse.ArgumentParser):
    """argparse that raises instead of exiting, for lines typed at a prompt."""

    def error(self, message: str):
        raise UsageError(message)

    def exit(self, status: int = 0, message: str | None = None):
        if message:
            print(message, file=sys.stderr, end="")
        raise UsageError("")


def line_parser() -> argparse.ArgumentParser:
    p = _LineParser(prog="", add_help=False)
    sub = p.add_subparsers(dest="command", required=True, parser_class=_LineParser)
    add_commands(sub, "shell", _LineParser)
    return p


class Session:
    """One long-lived station: the client, a lock around it, and the background thread that keeps it talking."""

    def __init__(self, client: Client, out: TextIO = sys.stdout,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        """``sleep``: how the background thread waits between exchanges (a test passes simulated time)."""
        self.client = client
        self.out = out
        self.sleep = sleep
        self.lock = threading.RLock()
        self.shown_events = len(client.gs.events)
        self.shown_texts = len(client.gs.texts)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._keep_alive, name="gcs-link", daemon=True)

    def __enter__(self) -> Session:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self.thread.join(2)

    def _keep_alive(self) -> None:
        """Heartbeat, teleop stream and retries while no command runs (a running command pumps by itself)."""
        while not self._stop.is_set():
            with self.lock:
                self.client.pump()
                self.report()
            self.sleep(IDLE_PUMP)

    def report(self) -> None:
        """Print the lease events and STATUSTEXTs that arrived since the last report."""
        gs = self.client.gs
        with self.lock:
            for e in gs.events[self.shown_events:]:
                print(f"[event {e.t:7.1f}] lease {e.expired} -> {e.current}  {e.reason}  ({e.holder})",
                      file=self.out, flush=True)
            for t, text in gs.texts[self.shown_texts:]:
                print(f"[vehicle {t:7.1f}] {text}", file=self.out, flush=True)
            self.shown_events, self.shown_texts = len(gs.events), len(gs.texts)

    def run_line(self, line: str, parser: argparse.ArgumentParser) -> int:
        """Execute one command line: 0 done, 1 refused, 2 bad command line."""
        try:
            words = shlex.split(line, comments=True)
        except ValueError as e:
            print(f"returnlink gcs: {e}", file=sys.stderr, flush=True)
            return 2
        if not words:
            return 0
        try:
            a = parser.parse_args(words)
            find(a.command_path).check(a, True)
            with self.lock:
                code = execute(Context(self.client, self.out, session=True), a)
                self.report()
            return code
        except UsageError as e:
            if str(e):
                print(f"returnlink gcs: {e}", file=sys.stderr, flush=True)
            return 2


def _topics() -> list[str]:
    return sorted({c.path.split(" ")[0] for c in COMMANDS if c.where != "oneshot"} | {"help", "quit"})


class Shell(cmd.Cmd):
    """The interactive prompt: ``readline`` history and completion of command names, ``help``."""

    intro = "returnlink ground station: `help` lists the commands, `quit` leaves (the link stays up meanwhile)."
    prompt = "returnlink> "

    def __init__(self, session: Session, stdin: TextIO | None = None) -> None:
        super().__init__(stdin=stdin)
        self.session = session
        self.parser = line_parser()

    def default(self, line: str) -> bool:
        try:
            self.session.run_line(line, self.parser)
        except KeyboardInterrupt:  # Ctrl-C ends the command (a long `wait`, `watch`), not the session
            with self.session.lock:
                self.session.client.gs.stop_streaming()
            print("\ninterrupted", file=self.session.out)
        return False

    def emptyline(self) -> bool:
        return False

    def do_quit(self, arg: str) -> bool:
        """leave the shell"""
        return True

    do_exit = do_quit

    def do_EOF(self, arg: str) -> bool:  # noqa: N802 - cmd's name for end of input
        print(file=self.session.out)
        return True

    def completenames(self, text: str, *ignored) -> list[str]:
        return [t for t in _topics() if t.startswith(text)]

    def completedefault(self, text: str, line: str, begidx: int, endidx: int) -> list[str]:
        head = line.split()[0] if line.split() else ""
        subs = [c.path.split(" ", 1)[1] for c in COMMANDS if c.path.startswith(head + " ")]
        return [s for s in subs if s.startswith(text)]

    def do_help(self, arg: str) -> None:
        """list the commands, or `help COMMAND` for its arguments"""
        out = self.session.out
        if arg:
            try:
                self.parser.parse_args([*shlex.split(arg), "--help"])
            except UsageError:
                pass
            except (KeyError, ValueError):
                print(f"no command {arg!r}", file=out)
            return
        for c in COMMANDS:
            if c.where != "oneshot":
                print(f"  {c.path:<14} {c.help}", file=out)
        print("  quit           leave the shell", file=out)


def run_script(session: Session, lines: TextIO) -> int:
    """Commands from a pipe or file, one per line (``#`` starts a comment): stop at the first refused or bad
    command with its exit code, else 0."""
    parser = line_parser()
    for n, line in enumerate(lines, 1):
        words = line.strip()
        if not words or words.startswith("#"):
            continue
        if words in ("quit", "exit"):
            break
        print(f"> {words}", file=session.out, flush=True)
        code = session.run_line(words, parser)
        if code:
            print(f"returnlink gcs shell: line {n} ({words!r}) failed, stopping", file=sys.stderr, flush=True)
            return code
    return 0


def run_shell(client: Client, stdin: TextIO = sys.stdin, out: TextIO = sys.stdout) -> int:
    """The long-lived session: interactive at a terminal, a script otherwise."""
    with Session(client, out) as session:
        if stdin.isatty():
            with contextlib.suppress(ImportError):
                import readline  # noqa: F401 - history and line editing for cmd's input()
            try:
                Shell(session).cmdloop()
            except KeyboardInterrupt:
                print(file=out)
            return 0
        try:
            return run_script(session, stdin)
        except KeyboardInterrupt:
            print("returnlink gcs shell: interrupted", file=sys.stderr)
            return 130
