"""The app's one home for threads, long jobs, their progress and their waits.

(About 530 lines: issue 12 asks for one module holding every job, wait and progress display.)

Engine and device calls stay synchronous; they take ``progress(step, total, message)`` and
``should_stop()`` (see :mod:`engine.progress`). This module runs them off the UI thread and
brings results back as Qt signals, delivered on the UI thread by queued connections.

- :class:`LatestWorker` (live preview, live camera view; napari's status-checker pattern): one
  background thread, a queue of length one. A new request replaces the pending one; the one
  being computed finishes and is delivered; ``synchronous=True`` computes inside
  :meth:`LatestWorker.submit` (tests, benchmarks).
- :class:`Job` (opening, saving, calibration, acquisition, noise reduction, export):
  ``fn(progress=, should_stop=)`` on a thread, with ``progress``/``finished``/``failed``/
  ``cancelled``/``ended`` signals, pause (``should_stop`` blocks while paused) and cancel
  (``should_stop`` returns True; the engine raises :class:`~engine.errors.Cancelled`);
  :meth:`Job.wait` is the only way the UI thread waits for one.
- :class:`JobProgress`: the one progress display (message, bar with count, time left by
  :class:`app.model.progress.TimeLeft`, Pause and Cancel) — in the status bar, the acquisition
  dock and the calibration wizard alike.
- :class:`UiCaller` / :class:`on_ui_thread`: a worker asks the UI thread to do something (show a
  projector frame in a Qt window) and waits until it is done; :func:`run_on_rig` is the body of
  every job that drives a rig (its lock, its projector on the UI thread).

superqt is not used: its ``ensure_main_thread`` re-raises the callable's exception inside a
slot on the UI thread (an exception escaping a Qt slot) and leaves the waiting worker to time
out, and its thread workers pause and abort through generators, not the engine's
``progress``/``should_stop`` callbacks.
"""

from __future__ import annotations

import itertools
import threading
import time
import traceback
import weakref
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QCoreApplication, QEventLoop, QObject, Qt, QThread, Signal, Slot
from PySide6.QtWidgets import QHBoxLayout, QLabel, QProgressBar, QPushButton, QSizePolicy, QVBoxLayout, QWidget

from app.model.progress import TimeLeft, format_duration
from engine.errors import Cancelled
from engine.progress import checkpoint


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

    def wait(self, timeout: float = 60.0, *, cancel: bool = False) -> bool:
        """Wait on the UI thread until the job has ended (its ``ended`` delivered), serving events.

        Events are processed meanwhile, so a worker blocked on a UI-thread call (a projector
        frame) can finish. With ``cancel`` the job is asked to stop first (at its next
        ``should_stop()``). Returns True once it has ended (False after ``timeout`` seconds).
        """
        if cancel:
            self.cancel()
        deadline = time.monotonic() + float(timeout)
        while self._running and time.monotonic() < deadline:
            QCoreApplication.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 20)
            self.join(0.005)
        return not self._running

    # ------------------------------------------------------------------ worker side
    def should_stop(self) -> bool:
        """For ``fn``: blocks while paused; True once cancelled."""
        self._run_gate.wait()
        return self._stop.is_set()

    def report(self, step: int, total: int, message: str) -> None:
        """For ``fn``: progress callback (direct on the job's own thread, queued from any other)."""
        if self.synchronous or QThread.currentThread() is self.thread():
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


# ---------------------------------------------------------------------------------- rigs
_LOCKS: weakref.WeakKeyDictionary[object, threading.Lock] = weakref.WeakKeyDictionary()
_LOCKS_GUARD = threading.Lock()


def rig_lock(rig) -> threading.Lock:
    """The lock a thread holds while it drives ``rig`` (live view, calibration, acquisition).

    Worker threads take it; the UI thread never waits on it (a live-view grab that finds it
    taken skips its frame).
    """
    with _LOCKS_GUARD:
        lock = _LOCKS.get(rig)
        if lock is None:
            lock = _LOCKS[rig] = threading.Lock()
        return lock


class _WorkerRig:
    """A rig as a worker thread sees it: ``projector`` calls run on the UI thread."""

    def __init__(self, rig, caller: UiCaller):
        self._rig = rig
        self.projector = on_ui_thread(rig.projector, caller)

    def __getattr__(self, name):
        return getattr(self._rig, name)


def worker_rig(rig, caller: UiCaller):
    """Wrap ``rig`` for a worker: projector methods marshalled to the UI thread by ``caller``.

    A projector may be a Qt window (``devices.qtscreen``), which only the UI thread may drive;
    the worker waits until the frame is shown. Everything else (camera, names) passes through.
    """
    return _WorkerRig(rig, caller)


def run_on_rig(fn: Callable, rig, *args, caller: UiCaller, progress=None, should_stop=None, **kwargs):
    """Job body of every rig job: take the rig's lock (still cancellable while waiting for it),
    then ``fn(worker_rig(rig), *args, progress=, should_stop=, **kwargs)``."""
    lock = rig_lock(rig)
    while not lock.acquire(timeout=0.05):
        checkpoint(should_stop, "waiting for the rig")
    try:
        return fn(worker_rig(rig, caller), *args, progress=progress, should_stop=should_stop, **kwargs)
    finally:
        lock.release()


# ---------------------------------------------------------------------------------- progress
class JobProgress(QWidget):
    """The progress of a :class:`Job`: message and time left, a bar reading "12 / 41 captures",
    Pause/Resume and Cancel.

    Parameters
    ----------
    name : str
        objectName prefix: the children are ``{name}_message``, ``{name}_bar``, ``{name}_pause``
        and ``{name}_cancel`` (see docs/ui.md).
    unit : str
        What a step is ("captures", "steps"); empty: the bar shows a percentage.
    stacked : bool
        The message under the bar (narrow docks) instead of beside it.
    hide_when_idle : bool
        Shown only while a job runs (the status bar).
    buttons : bool
        Lay Pause and Cancel out beside the bar (False: the owner places them).
    clock : callable
        For :class:`~app.model.progress.TimeLeft` (tests pass a fake one).
    """

    def __init__(self, name: str, *, unit: str = "", stacked: bool = False, hide_when_idle: bool = False,
                 buttons: bool = True, clock: Callable[[], float] = time.monotonic, parent: QWidget | None = None):
        super().__init__(parent)
        self.setObjectName(name)
        self.unit = unit
        self.hide_when_idle = hide_when_idle
        self.time_left = TimeLeft(clock=clock)
        self.label = QLabel(objectName=f"{name}_message")
        self.label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.label.setWordWrap(stacked)
        self.bar = QProgressBar(objectName=f"{name}_bar")
        self.bar.setTextVisible(True)
        self.pause = QPushButton("Pause", objectName=f"{name}_pause", checkable=True)
        self.cancel = QPushButton("Cancel", objectName=f"{name}_cancel")
        controls = QHBoxLayout()
        controls.setContentsMargins(0, 0, 0, 0)
        controls.addWidget(self.bar, 1)
        if buttons:  # else the owner lays :attr:`pause` and :attr:`cancel` out beside its own Start
            controls.addWidget(self.pause)
            controls.addWidget(self.cancel)
        lay = QVBoxLayout(self) if stacked else QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        if stacked:
            lay.addLayout(controls)
            lay.addWidget(self.label)
        else:
            lay.addWidget(self.label, 3)
            lay.addLayout(controls, 2)
        self.job: Job | None = None
        self.pause.toggled.connect(self._on_pause)
        self.cancel.clicked.connect(self._on_cancel)
        self.reset()

    def reset(self, note: str = "") -> None:
        """Idle: an empty bar, ``note`` as the message."""
        self.time_left.reset()
        self.bar.setRange(0, 1)
        self.bar.setValue(0)
        self.bar.setFormat(f"0 / 0 {self.unit}" if self.unit else "%p%")
        self._say(note)
        self._set_paused(False)
        self.pause.setEnabled(False)
        self.cancel.setEnabled(False)
        self.setVisible(not self.hide_when_idle)

    def attach(self, job: Job, *, pausable: bool = True, cancellable: bool = True) -> None:
        """Follow ``job`` until it ends; Pause and Cancel are shown only where the job honours them."""
        self.reset(job.name + "…")
        self.job = job
        self.bar.setRange(0, 0)  # busy until the first report
        self.pause.setVisible(pausable)
        self.cancel.setVisible(cancellable)
        self.pause.setEnabled(True)
        self.cancel.setEnabled(True)
        job.progress.connect(self.update_progress)
        job.paused.connect(self._set_paused)
        job.finished.connect(lambda _r: self._end("done"))
        job.failed.connect(lambda exc: self._end(f"failed: {exc}"))
        job.cancelled.connect(lambda _e: self._end("cancelled"))
        self.show()

    def update_progress(self, step: int, total: int, message: str) -> None:
        """Slot for :attr:`Job.progress`."""
        if total <= 0:
            self._say(message)
            return
        total = max(int(total), int(step), 1)
        self.bar.setRange(0, total)
        self.bar.setValue(int(step))
        self.bar.setFormat(f"{int(step)} / {total} {self.unit}" if self.unit else "%p%")
        seconds = self.time_left.update(step, total)
        left = "" if seconds is None or step >= total else f" · about {format_duration(seconds)} left"
        self._say(f"{message}{left}")

    def _say(self, message: str) -> None:
        """Show ``message``; the label is cut short in a narrow status bar, so it is the tooltip too."""
        self.label.setText(message)
        self.label.setToolTip(message)

    @property
    def seconds_left(self) -> float | None:
        return self.time_left.seconds

    def _on_pause(self, on: bool) -> None:
        if self.job is not None:
            self.job.pause() if on else self.job.resume()

    def _on_cancel(self) -> None:
        if self.job is not None:
            self.job.cancel()

    def _set_paused(self, on: bool) -> None:
        self.pause.blockSignals(True)
        self.pause.setChecked(on)
        self.pause.blockSignals(False)
        self.pause.setText("Resume" if on else "Pause")
        if on:
            self._say("paused")

    def _end(self, note: str) -> None:
        self.job = None
        self._set_paused(False)
        self.pause.setEnabled(False)
        self.cancel.setEnabled(False)
        if self.bar.maximum() == 0:
            self.bar.setRange(0, 1)
        self._say(note)
        if self.hide_when_idle:
            self.hide()
