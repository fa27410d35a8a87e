"""Entry point of the desktop app: ``app.qt.gui.main(argv)``.

``albedit`` with no argument opens the virtual-rig demo (``virtual:cornell``: the rig's
photograph with the scene targets painted, ground truth available); ``albedit PATH`` opens a
session folder or an image.
"""

from __future__ import annotations

import sys
from pathlib import Path

from PySide6.QtCore import QTimer
from PySide6.QtGui import QIcon
from PySide6.QtWidgets import QApplication

from app.qt.main_window import APP_NAME, MainWindow

#: The application icon (SVG, rendered by Qt at every size).
ICON = Path(__file__).resolve().parents[2] / "resources" / "icons" / "albedit.svg"


def main(argv: list[str] | None = None) -> int:
    """Create the QApplication, open the main window and run the event loop.

    Parameters
    ----------
    argv : list of str, optional
        Arguments after the program name: nothing (the virtual-rig demo) or one path (a
        session folder or an image). Default ``sys.argv[1:]``.

    Returns
    -------
    int
        The event loop's exit code.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    app = QApplication.instance() or QApplication([sys.argv[0] if sys.argv else "albedit"])
    app.setApplicationName(APP_NAME)
    app.setOrganizationName(APP_NAME)
    app.setWindowIcon(QIcon(str(ICON)))
    window = MainWindow()
    window.show()
    if args:
        QTimer.singleShot(0, lambda: window.open_path(args[0]))
    else:
        QTimer.singleShot(0, window.open_demo)
    return int(app.exec())


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
