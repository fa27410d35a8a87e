"""The desktop app (PySide6): windows, docks, wizard pages, canvas and the worker threads."""
