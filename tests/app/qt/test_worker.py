"""The app's threads: latest-request-wins preview worker, long jobs, UI-thread calls."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from app.model.display import to_rgb32
from app.model.views import CanvasView
from app.qt.preview import PreviewController
from app.qt.worker import Job, LatestWorker, UiCaller, on_ui_thread
from engine.errors import Cancelled
from engine.progress import checkpoint, report
from engine.recolor import prepare_preview, recolor_preview


def test_latest_request_wins(qtbot):
    gate = threading.Event()
    computed = []

    def fn(x):
        if x == 0:
            gate.wait(5)
        computed.append(x)
        return x * 10

    worker = LatestWorker(fn)
    results = []
    worker.done.connect(lambda rid, r: results.append((rid, r)))
    first = worker.submit(0)  # blocks the thread until the gate opens
    qtbot.waitUntil(lambda: not worker.idle() and worker._pending is None)
    ids = [worker.submit(i) for i in range(1, 6)]  # each replaces the previous pending one
    gate.set()
    qtbot.waitUntil(lambda: len(results) == 2 and worker.idle())
    assert computed == [0, 5]
    assert results == [(first, 0), (ids[-1], 50)]
    worker.close()


def test_failures_are_signalled(qtbot):
    worker = LatestWorker(lambda x: 1 / x, synchronous=True)
    with qtbot.waitSignal(worker.failed) as blocker:
        worker.submit(0)
    assert isinstance(blocker.args[1], ZeroDivisionError)


def test_preview_drops_stale_results(qtbot, acquired_doc):
    preview = PreviewController(acquired_doc, max_shape=(24, 32), synchronous=True)
    frames = []
    preview.frame_ready.connect(frames.append)
    rid = preview.request()
    stale = preview.frame
    preview.worker.done.emit(rid - 1, stale)  # an older result arriving late
    preview.rebuild()
    preview.worker.done.emit(rid + 100, stale)  # a result from the replaced renderer
    assert frames[-1].generation == preview.generation and sum(f is stale for f in frames) == 1
    preview.close()


def test_preview_follows_kappa_of_the_last_cascade_target(qtbot, acquired_doc):
    doc = acquired_doc
    preview = PreviewController(doc, max_shape=(24, 32), synchronous=True)
    d = doc.decomposition
    doc.set_kappa(doc.by_name("wall").uid, [3.0, 1.0, 0.25])
    expected = recolor_preview(prepare_preview(d, (24, 32)), [3.0, 1.0, 0.25])
    np.testing.assert_array_equal(preview.frame.pixels, to_rgb32(expected))
    n = preview.frame.request_id
    doc.set_kappa(doc.add_target("unacquired").uid, 5.0)  # not in the cascade: no new frame
    assert preview.frame.request_id == n
    preview.set_view(CanvasView.TRUTH)  # ground truth depends on every target's κ and mask
    calls = doc.truth.calls
    doc.set_kappa(doc.by_name("unacquired").uid, 4.0)
    assert preview.frame.request_id > n and doc.truth.calls == calls  # empty mask: same edit, cached
    preview.close()


def _work(n, *, progress=None, should_stop=None, fail=False):
    for i in range(n):
        checkpoint(should_stop, "work")
        report(progress, i, n, f"step {i}")
        if fail and i == 2:
            raise ValueError("the engine's message")
    return n


@pytest.mark.parametrize("synchronous", [True, False])
def test_job_reports_progress_and_result(qtbot, synchronous):
    job = Job(_work, 4, name="Testing", synchronous=synchronous)
    steps = []
    job.progress.connect(lambda s, t, m: steps.append((s, t, m)))
    with qtbot.waitSignal(job.finished, timeout=5000) as blocker:
        job.start()
    assert blocker.args == [4] and steps[-1] == (3, 4, "step 3") and not job.running


def test_job_failure_carries_the_message(qtbot):
    job = Job(_work, 5, fail=True)
    with qtbot.waitSignal(job.failed, timeout=5000) as blocker:
        job.start()
    assert str(blocker.args[0]) == "the engine's message" and "ValueError" in job.traceback


def _looping_job():
    """A job that loops until stopped, and the event set once it runs."""
    entered = threading.Event()

    def fn(progress=None, should_stop=None):
        entered.set()
        while True:
            checkpoint(should_stop, "the loop")

    return Job(fn), entered


def test_job_pause_and_cancel(qtbot):
    job, entered = _looping_job()
    paused = []
    job.paused.connect(paused.append)
    job.start()
    assert entered.wait(5)
    job.pause()
    assert job.is_paused
    with qtbot.waitSignal(job.cancelled, timeout=5000) as blocker:
        job.cancel()
    assert isinstance(blocker.args[0], Cancelled) and "cancelled" in str(blocker.args[0])
    assert paused == [True, False] and job.join(5)


def test_worker_drives_the_ui_thread_and_waits(qtbot):
    """A projector window must be shown from the UI thread while the acquisition waits."""
    ui_thread = threading.current_thread()

    class Screen:
        resolution = (2, 2)

        def __init__(self):
            self.shown = []

        def show(self, image):
            assert threading.current_thread() is ui_thread
            self.shown.append(image.sum())
            return "on the wall"

    screen = Screen()
    caller = UiCaller()
    projector = on_ui_thread(screen, caller)

    def acquire(progress=None, should_stop=None):
        answers = [projector.show(np.full((2, 2, 3), i, np.float32)) for i in range(3)]
        return answers, projector.resolution

    job = Job(acquire)
    with qtbot.waitSignal(job.finished, timeout=5000) as blocker:
        job.start()
    assert blocker.args[0] == (["on the wall"] * 3, (2, 2))
    assert screen.shown == [0.0, 12.0, 24.0]
    assert caller.call(lambda: 7) == 7  # on the UI thread itself: a direct call


def test_threaded_preview_delivers_the_latest_frame(qtbot, acquired_doc):
    doc = acquired_doc
    preview = PreviewController(doc, max_shape=(24, 32))  # the app's default: a worker thread
    wall = doc.by_name("wall").uid
    for v in (1.5, 2.0, 3.0, 4.0):
        doc.set_kappa(wall, [v, 1.0, 1.0])
    qtbot.waitUntil(lambda: preview.frame is not None and preview.frame.request_id == preview.last_id, timeout=5000)
    expected = recolor_preview(prepare_preview(doc.decomposition, (24, 32)), [4.0, 1.0, 1.0])
    np.testing.assert_array_equal(preview.frame.pixels, to_rgb32(expected))
    preview.close()


def test_pause_after_cancel_does_not_hold_the_job(qtbot):
    job, entered = _looping_job()
    job.start()
    assert entered.wait(5)
    with qtbot.waitSignal(job.cancelled, timeout=5000):
        job.cancel()
        job.pause()  # e.g. a Pause click racing the Cancel click
    assert not job.is_paused and job.join(5)
