"""The app's only threads: a latest-request-wins preview worker and a long-job runner.

Engine and device calls stay synchronous; they take ``progress(step, total, message)`` and
``should_stop()`` (see :mod:`engine.progress`). This module runs them off the UI thread and
brings results back as Qt signals, delivered on the UI thread by queued connections.

- :class:`LatestWorker` (live preview, napari's status-checker pattern): one background thread,
  a queue of length one. A new request replaces the pending one; the one being computed
  finishes and is delivered; the receiver drops anything older than what it shows.
  ``synchronous=True`` computes inside :meth:`LatestWorker.submit` (tests, benchmarks).
- :class:`Job` (calibration, acquisition, decomposition, export): ``fn(progress=,
  should_stop=)`` on a thread, with ``progress``/``finished``/``failed``/``cancelled``
  signals, pause (``should_stop`` blocks while paused) and cancel (``should_stop`` returns
  True; the engine raises :class:`~engine.errors.Cancelled`).
- :class:`UiCaller` / :func:`on_ui_thread`: a worker asks the UI thread to do something (show a
  projector frame in a Qt window) and waits until it is done.
"""

from __future__ import annotations

import itertools
import threading
import traceback
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QCoreApplication, QObject, Qt, QThread, Signal, Slot

from engine.errors import Cancelled


def _on_ui_thread() -> bool:
    app = QCoreApplication.instance()
    return app is None or QThread.currentThread() is app.thread()


class LatestWorker(QObject):
    """Computes ``fn(payload)`` on one background thread; the newest request wins.

    Signals
    -------
    done(int, object)
        Request id and result, on the UI thread. Ids increase with each submit.
    failed(int, object)
        Request id and the exception ``fn`` raised.
    """

    done = Signal(int, object)
    failed = Signal(int, object)
    _deliver = Signal(int, object, bool)

    def __init__(self, fn: Callable[[Any], Any], *, synchronous: bool = False, parent: QObject | None = None):
        super().__init__(parent)
        self.fn = fn
        self.synchronous = synchronous
        self._ids = itertools.count(1)
        self._cond = threading.Condition()
        self._pending: tuple[int, Any] | None = None
        self._closed = False
        self._busy = False
        self._thread: threading.Thread | None = None
        self._deliver.connect(self._on_deliver, Qt.ConnectionType.QueuedConnection)

    def submit(self, payload: Any) -> int:
        """Queue ``payload`` (replacing any request not started yet); returns its id."""
        rid = next(self._ids)
        if self.synchronous:
            self._run(rid, payload, direct=True)
            return rid
        with self._cond:
            if self._closed:
                raise RuntimeError("the preview worker is closed")
            self._pending = (rid, payload)
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name="albedit-preview", daemon=True)
                self._thread.start()
            self._cond.notify()
        return rid

    def idle(self) -> bool:
        """True when nothing is pending or being computed."""
        with self._cond:
            return self._pending is None and not self._busy

    def close(self, timeout: float = 5.0) -> None:
        """Stop the thread after the current request (pending ones are dropped)."""
        with self._cond:
            self._closed = True
            self._pending = None
            self._cond.notify()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def _loop(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                rid, payload = self._pending
                self._pending = None
                self._busy = True
            try:
                self._run(rid, payload, direct=False)
            finally:
                with self._cond:
                    self._busy = False

    def _run(self, rid: int, payload: Any, *, direct: bool) -> None:
        try:
            result, ok = self.fn(payload), True
        except Exception as exc:  # delivered as a signal, shown by the UI
            result, ok = exc, False
        if direct:
            self._on_deliver(rid, result, ok)
        else:
            self._deliver.emit(rid, result, ok)

    @Slot(int, object, bool)
    def _on_deliver(self, rid: int, result: Any, ok: bool) -> None:
        (self.done if ok else self.failed).emit(rid, result)


class UiCaller(QObject):
    """Runs callables on the UI thread for worker threads, which wait for the result.

    Create it on the UI thread. From the UI thread itself, :meth:`call` runs the callable directly.
    """

    _invoke = Signal(object)

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self._invoke.connect(self._run, Qt.ConnectionType.QueuedConnection)

    def call(self, fn: Callable, *args, timeout: float | None = None, **kwargs):
        """``fn(*args, **kwargs)`` on the UI thread; returns its result or re-raises its error.

        Raises
        ------
        TimeoutError
            The UI thread did not run it within ``timeout`` seconds.
        """
        if QThread.currentThread() is self.thread():
            return fn(*args, **kwargs)
        box: dict[str, Any] = {"event": threading.Event()}
        self._invoke.emit((fn, args, kwargs, box))
        if not box["event"].wait(timeout):
            raise TimeoutError(f"the UI thread did not run {getattr(fn, '__name__', fn)!r} within {timeout} s")
        if "error" in box:
            raise box["error"]
        return box.get("result")

    @Slot(object)
    def _run(self, item) -> None:
        fn, args, kwargs, box = item
        try:
            box["result"] = fn(*args, **kwargs)
        except BaseException as exc:  # handed back to the waiting worker
            box["error"] = exc
        finally:
            box["event"].set()


class on_ui_thread:  # noqa: N801 - used like a function: on_ui_thread(projector, caller)
    """Proxy whose method calls run on the UI thread (e.g. a Qt projector window's ``show``).

    Attribute reads pass through; calls to methods are marshalled by ``caller`` and block the
    worker until the UI thread returns.
    """

    def __init__(self, target: Any, caller: UiCaller):
        object.__setattr__(self, "_target", target)
        object.__setattr__(self, "_caller", caller)

    def __getattr__(self, name: str):
        value = getattr(self._target, name)
        if not callable(value):
            return value

        def call(*args, **kwargs):
            return self._caller.call(value, *args, **kwargs)

        call.__name__ = name
        return call

    def __setattr__(self, name: str, value) -> None:
        self._caller.call(setattr, self._target, name, value)


class Job(QObject):
    """A long job ``fn(*args, progress=..., should_stop=..., **kwargs)`` on a worker thread.

    Signals (on the UI thread)
    --------------------------
    progress(int, int, str)
        step, total, message.
    finished(object)
        The return value.
    failed(object)
        The exception (its message is the engine's, shown in a dialog by the app).
    cancelled(object)
        The :class:`~engine.errors.Cancelled` exception after a cancel.
    paused(bool)
        Pause state changed.
    ended()
        After any of finished / failed / cancelled.

    Parameters
    ----------
    fn : callable
    name : str
        What the progress display says ("Exporting").
    synchronous : bool
        Run in :meth:`start`'s thread (tests); signals are emitted directly.
    """

    progress = Signal(int, int, str)
    finished = Signal(object)
    failed = Signal(object)
    cancelled = Signal(object)
    paused = Signal(bool)
    ended = Signal()
    _progress = Signal(int, int, str)
    _end = Signal(str, object)

    def __init__(self, fn: Callable, *args, name: str = "Working", synchronous: bool = False,
                 parent: QObject | None = None, **kwargs):
        super().__init__(parent)
        self.fn, self.args, self.kwargs = fn, args, kwargs
        self.name = name
        self.synchronous = synchronous
        self.ui = UiCaller(self)
        self._stop = threading.Event()
        self._run_gate = threading.Event()
        self._run_gate.set()
        self._thread: threading.Thread | None = None
        self._running = False
        self.traceback = ""
        self._progress.connect(self.progress, Qt.ConnectionType.QueuedConnection)
        self._end.connect(self._on_end, Qt.ConnectionType.QueuedConnection)

    # ------------------------------------------------------------------ control (UI thread)
    def start(self) -> Job:
        if self._running or self._thread is not None:
            raise RuntimeError(f"job {self.name!r} was already started")
        self._running = True
        if self.synchronous:
            self._body(direct=True)
        else:
            self._thread = threading.Thread(target=self._body, kwargs={"direct": False},
                                            name=f"albedit-job-{self.name}", daemon=True)
            self._thread.start()
        return self

    def cancel(self) -> None:
        """Ask the job to stop at its next ``should_stop()``; also ends a pause."""
        self._stop.set()
        if self.is_paused:
            self._run_gate.set()
            self.paused.emit(False)

    def pause(self) -> None:
        """Hold the job at its next ``should_stop()`` until :meth:`resume` or :meth:`cancel`.

        A cancelled job is not paused: it must reach its next ``should_stop()`` and end.
        """
        if self._running and self._run_gate.is_set() and not self._stop.is_set():
            self._run_gate.clear()
            self.paused.emit(True)

    def resume(self) -> None:
        if not self._run_gate.is_set():
            self._run_gate.set()
            self.paused.emit(False)

    @property
    def running(self) -> bool:
        return self._running

    @property
    def is_paused(self) -> bool:
        return not self._run_gate.is_set()

    def join(self, timeout: float | None = None) -> bool:
        """Wait for the thread (NOT on the UI thread while the job may call :attr:`ui`). True if done."""
        if self._thread is not None:
            self._thread.join(timeout)
            return not self._thread.is_alive()
        return True

    # ------------------------------------------------------------------ worker side
    def should_stop(self) -> bool:
        """For ``fn``: blocks while paused; True once cancelled."""
        self._run_gate.wait()
        return self._stop.is_set()

    def report(self, step: int, total: int, message: str) -> None:
        """For ``fn``: progress callback."""
        if self.synchronous or _on_ui_thread():
            self.progress.emit(int(step), int(total), str(message))
        else:
            self._progress.emit(int(step), int(total), str(message))

    def _body(self, *, direct: bool) -> None:
        try:
            result = self.fn(*self.args, progress=self.report, should_stop=self.should_stop, **self.kwargs)
            outcome = ("finished", result)
        except Cancelled as exc:
            outcome = ("cancelled", exc)
        except Exception as exc:
            self.traceback = traceback.format_exc()
            outcome = ("failed", exc)
        if direct:
            self._on_end(*outcome)
        else:
            self._end.emit(*outcome)

    @Slot(str, object)
    def _on_end(self, kind: str, value: Any) -> None:
        self._running = False
        if self.is_paused:
            self._run_gate.set()
            self.paused.emit(False)
        getattr(self, kind).emit(value)
        self.ended.emit()
