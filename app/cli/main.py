"""The headless ``albedit`` subcommands for lab techs and batch work.

``albedit demo``, ``calibrate``, ``capture``, ``checker``, ``recolor``, ``export``, ``devices`` and ``bench``
report progress on stderr, print one-line errors and exit non-zero on failure.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from collections.abc import Callable

from app.model.progress import TimeLeft, format_duration
from engine.errors import AlbeditError

#: subcommand name -> (module, one-line help); modules expose add_arguments(parser) and run(args)
COMMANDS = {
    "demo": ("app.cli.demo", "run the whole pipeline on the virtual Cornell box and score it against ground truth"),
    "calibrate": ("app.cli.calibrate", "calibrate a rig (black frame, projector response, Gray-code correspondences)"),
    "capture": ("app.cli.capture", "capture the observations of one target (or a cascade) into a session"),
    "checker": ("app.cli.checker", "measure a colour checker in a session's scene (absolute albedo)"),
    "recolor": ("app.cli.recolor", "recolor a captured session's target (kappa, colour, albedo or match), write it"),
    "export": ("app.cli.export", "export a session's saved edit (targets and kappa) as EXR, TIFF or PNG"),
    "devices": ("app.cli.devices", "list the rigs this machine can open and take one frame from one"),
    "bench": ("app.cli.bench", "run the engine benchmarks"),
}


class ProgressBar:
    """A progress report on stderr, usable as an engine ``progress`` callback.

    On a terminal it is one line redrawn in place; written to a file or a pipe (a log) it is a
    line per tenth of the work, so a log reads as a short list, not as thousands of carriage
    returns.
    """

    #: a bar's line is on the terminal without its newline (an error must start a line of its own)
    unfinished = False

    def __init__(self, stream=None, *, width: int = 28):
        self.stream = stream or sys.stderr
        self.width = width
        self.start = time.monotonic()
        self._last = ""
        self.time_left = TimeLeft()  # the app's rule: a resumed run's instant first steps do not count
        self._logged: int | None = None
        isatty = getattr(self.stream, "isatty", None)
        self.terminal = bool(isatty and isatty())

    def __call__(self, step: int, total: int, message: str) -> None:
        frac = 0.0 if total <= 0 else min(1.0, step / total)
        if not self.terminal:
            self._log(step, total, frac, message)
            return
        filled = int(round(frac * self.width))
        left = self.time_left.update(step, total)
        eta = f" ~{format_duration(left)} left" if left is not None and 0 < frac < 1 else ""
        line = f"\r[{'#' * filled}{'.' * (self.width - filled)}] {step}/{total} {message[:48]:<48}{eta}"
        if line != self._last:
            self.stream.write(line)
            self.stream.flush()
            self._last = line
            ProgressBar.unfinished = True
        if total > 0 and step >= total:
            self.stream.write("\n")
            self._last = ""
            ProgressBar.unfinished = False

    def _log(self, step: int, total: int, frac: float, message: str) -> None:
        tenth = int(frac * 10)
        if tenth == self._logged:
            return
        self._logged = tenth
        self.stream.write(f"[{step}/{total}] {message} ({time.monotonic() - self.start:.0f} s)\n")
        self.stream.flush()


def _end_progress_line() -> None:
    if ProgressBar.unfinished:
        sys.stderr.write("\n")
        ProgressBar.unfinished = False


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line: what is wrong, and where to read more."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")


#: a value that argparse would take for an option because it starts with '-' (it only knows plain numbers)
_NEGATIVE_VALUE = re.compile(r"-\.?[0-9]")


def _attach_negative_values(argv: list[str]) -> list[str]:
    """Write ``--kappa -1,1,1`` as ``--kappa=-1,1,1`` so that the value reaches its option's check."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        token = argv[i]
        if token.startswith("--") and token != "--" and "=" not in token and i + 1 < len(argv) \
                and _NEGATIVE_VALUE.match(argv[i + 1]):
            out.append(f"{token}={argv[i + 1]}")
            i += 2
        else:
            out.append(token)
            i += 1
    return out


def build_parser() -> argparse.ArgumentParser:
    import importlib

    parser = _Parser(
        prog="albedit",
        description="Measurement-based editing of diffuse albedo with consistent interreflections.",
        epilog="Without a subcommand, opens the desktop app (on the virtual rig demo, or on SESSION).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        importlib.import_module(module).add_arguments(p)
        p.set_defaults(_module=module)
    return parser


def run_command(argv: list[str] | None = None) -> int:
    """Parse ``argv`` (a subcommand and its options), run it, and return the exit status."""
    argv = _attach_negative_values(list(sys.argv[1:] if argv is None else argv))
    args = build_parser().parse_args(argv)
    if args.command is None:
        build_parser().print_help()
        return 2
    import importlib

    run: Callable = importlib.import_module(args._module).run
    try:
        return int(run(args) or 0)
    except KeyboardInterrupt:
        _end_progress_line()
        print("albedit: interrupted; finished captures are kept in the session", file=sys.stderr)
        return 130
    except AlbeditError as exc:
        _end_progress_line()
        print(f"albedit {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(run_command())
