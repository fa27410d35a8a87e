"""``albedit``: the desktop app, or a headless subcommand.

``albedit`` alone (or with a session folder or an image) opens the desktop app; ``albedit
demo``, ``calibrate``, ``capture``, ``recolor``, ``export``, ``devices`` and ``bench`` run
headless (:mod:`app.cli.main`).
"""

from __future__ import annotations

import sys

from app.cli.main import COMMANDS, run_command


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``albedit`` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] in (["--version"], ["-V"]):
        import app

        print(f"albedit {app.__version__}")
        return 0
    if not argv or (argv[0] not in COMMANDS and not argv[0].startswith("-")):
        from app.qt.gui import main as gui_main

        return gui_main(argv)
    return run_command(argv)


if __name__ == "__main__":
    sys.exit(main())
