"""The session's noise-aware recolor data (:mod:`engine.trust`): cached, else prepared from its captures.

The noise-aware recolor needs the acquisition's observations and their covariance, not only
the decomposition. They are rebuilt from the session's own captures (the plan's cascade run
offline, :func:`engine.workflow.decomposition.reacquired`), the last target's
:meth:`engine.acquire.PreparedTarget.trust` smooths every order's shares once, and the result
is cached under :func:`trusted_key` of the decomposition's key — a changed acquisition has
another key, so it is prepared again. κ comes later: :func:`engine.trust.recolor_trusted`.
"""

from __future__ import annotations

from engine.errors import InputError, SessionError
from engine.progress import Progress, ShouldStop, checkpoint, report
from engine.session import Session
from engine.trust import TrustedDecomposition
from engine.workflow.decomposition import decomposition_key, discard_unusable, reacquired

__all__ = ["NoNoiseModel", "TRUST_VERSION", "load_trusted", "trusted_key"]

#: Bump when the noise-aware preparation's maths or layout change: older cache entries are prepared again.
TRUST_VERSION = 4


class NoNoiseModel(SessionError):
    """The acquisition carries no camera-noise model, so only the plain recolor is possible."""


def trusted_key(key: str) -> str:
    """Cache key of the noise-aware data of the decomposition cached under ``key``.

    Examples
    --------
    >>> trusted_key("decomposition-0123456789abcdef")
    'decomposition-0123456789abcdef-trusted4'
    """
    return f"{key}-trusted{TRUST_VERSION}"


def load_trusted(session: Session, key: str | None = None, *, rig=None, notes: list[str] | None = None,
                 progress: Progress | None = None, should_stop: ShouldStop | None = None) -> TrustedDecomposition:
    """The session's acquisition ready for :func:`engine.trust.recolor_trusted`: cached, else prepared.

    Parameters
    ----------
    session : Session
    key : str, optional
        The decomposition's cache key (a saved edit's); default
        :func:`engine.workflow.decomposition_key` of the session's plan.
    rig : RigLike, optional
        Where to take captures the session lacks (normally none).
    notes : list of str, optional
        Receives a line when a cache entry was unusable and the data was prepared again.
    progress, should_stop
        :mod:`engine.progress` conventions.

    Returns
    -------
    TrustedDecomposition
        Of the last cascade target (earlier targets' κ are already in its observations).

    Raises
    ------
    NoNoiseModel
        The captures carry no noise model (the camera's noise was not measured before they
        were taken): only the plain recolor is possible.
    SessionError
        No acquisition in the session, a capture needed is missing, or an order-1 acquisition
        (the photograph only: the plain recolor is κ times it, nothing to weigh).
    Cancelled
        Stopped on request.

    Notes
    -----
    Preparing costs seconds (bench/trusted.py: 11 s at 512², order 4, on this 2-core
    machine); reading the cache entry back costs milliseconds. A session that cannot be
    written (read-only, locked) still gets the result, uncached.
    """
    name = trusted_key(key or decomposition_key(session))
    arrays = session.cache_get(name)
    if arrays is not None:
        try:
            trusted = TrustedDecomposition.from_arrays(arrays)
            if trusted.photograph.shape[:2] != tuple(session.camera_resolution):
                raise InputError(f"it is {trusted.photograph.shape[:2]}, the session {session.camera_resolution}")
            return trusted
        except InputError as exc:
            discard_unusable(session, name, f"the cached noise-aware data {name!r} was unusable ({exc}); prepared "
                             "it again", notes)
    if (session.state.get("plan") or {}).get("order") == 1:  # known before the replay ("auto" captures 2 or more)
        # prepare_trust would have no order to smooth, nor a target to recolor
        raise SessionError(f"the acquisition in {session.path} is of order 1 (the photograph only): no interaction "
                           "component to weigh against its noise; recolored plainly (κ times the photograph on the "
                           "target)")
    read = [0]  # the replay's capture count: it is most of the work (10-40 s on large sessions), then one step

    def reading(step, total, _message=""):
        read[0] = max(int(total), int(step))
        report(progress, step, read[0] + 1, "reading the acquisition's captures")

    reading(0, 1)
    result = reacquired(session, rig, should_stop=should_stop, progress=reading if progress is not None else None)
    acq = result.acquisition
    if acq.covariance is None:
        raise NoNoiseModel(f"the acquisition in {session.path} carries no noise model (captured before the camera's "
                           "noise was measured): recolored plainly; recalibrate and capture again for the "
                           "noise-aware recolor")
    checkpoint(should_stop, "preparing the noise-aware recolor")
    report(progress, read[0], read[0] + 1, "smoothing the interaction shares (once per acquisition)")
    trusted = result.targets[-1][1].trust(acq.observations, acq.covariance, should_stop=should_stop)
    try:
        session.cache_put(name, trusted.to_arrays())
    except (OSError, SessionError):
        pass  # a read-only session: the result is returned all the same
    report(progress, read[0] + 1, read[0] + 1, "noise-aware recolor ready")
    return trusted
