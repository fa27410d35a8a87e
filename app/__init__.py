"""Albedit's front ends, in three rooms.

- :mod:`app.model` — the editing model without Qt: document, targets, undo commands, painting,
  rendering, opening and saving documents, the demo.
- :mod:`app.qt` — the desktop app: windows, docks, wizard pages, canvas, workers.
- :mod:`app.cli` — the headless ``albedit`` subcommands, without Qt.

:mod:`app.main` is the ``albedit`` console script: a subcommand runs headless, anything else
opens the desktop app. Import-linter contracts in ``pyproject.toml`` keep Qt out of
``app.model`` and ``app.cli``.
"""

from importlib.metadata import PackageNotFoundError, version

#: The application's name (window titles, QSettings).
APP_NAME = "Albedit"

try:
    __version__ = version("albedit")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "unknown"
