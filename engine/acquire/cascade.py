"""Multi-target acquisition: Algorithm 1 of the paper generalised to T targets (Sec. 4).

Targets are recolored in a user-given order. The κ of every target but the last is fixed
before capture, because it shapes the light emitted afterwards; the last target's κ stays
free. ``recolored(ℓ, lighting)`` — the scene under ``lighting`` with targets ``0..ℓ-1``
recolored — is, for ℓ = 0, a capture; for ℓ ≥ 1, a decomposition of target ℓ-1 from
``recolored(ℓ-1, ·)`` observations (the photograph under ``lighting``, then re-emissions on
target ℓ-1), recolored with its fixed κ. The last target's observations are
``recolored(T-1, ·)`` of its own re-emissions. Brute force costs K^T images; a single
target (T = 1) is Sec. 3.3's K images.

Adaptive capture (Sec. 5) replaces captures by predictions from every light already emitted
on the same target (:mod:`engine.acquire.predict`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.acquire.emission import Emitter
from engine.acquire.noise import Noise, covariance_stack
from engine.acquire.predict import Adaptive, Policy, Predictor, relative_error
from engine.acquire.recorder import Recorder
from engine.acquire.steps import Acquisition, CaptureSettings, EmittedNoise, reemit
from engine.acquire.target import PreparedTarget, pattern_budget, prepare_target
from engine.calibrate import Calibration
from engine.checks import check_kappa, check_order
from engine.errors import InputError
from engine.figurate import MAX_ORDER
from engine.progress import report
from engine.recolor import recolor
from engine.session.edit import mask_digest, mask_name
from engine.session.paths import NAME
from engine.text import counted
from engine.trust import recolor_trusted

#: The names of an acquisition's captures start with this and a hyphen (``acq-photograph``, ``acq-0``, ...).
CAPTURE_PREFIX = "acq"


@dataclass(frozen=True, eq=False)
class CascadeResult:
    """What a cascade produced: the last target's acquisition and the bookkeeping.

    Attributes
    ----------
    acquisition : Acquisition
        Observations of the last target, with the earlier targets recolored by their fixed κ
        — decompose them with the last target's mask and recolor with its free κ.
    targets : list of (str, PreparedTarget)
        Every target in cascade order.
    fixed_kappa : list of (3,) float
        κ of targets 0..T-2, fixed before capture (the app locks their sliders).
    images : int
        Observation images captured (the paper's count; a per-channel image is 3 camera shots).
    predicted : int
        Observation images predicted instead of captured (a predicted recolored observation at
        cascade level ℓ stands for the K^ℓ images its decomposition would have taken).
    captures : int
        Camera shots taken for observations (D measurement excluded).
    """

    acquisition: Acquisition
    targets: list
    fixed_kappa: list
    images: int
    predicted: int
    captures: int
    log: list = field(default_factory=list)

    def report(self, shots: int) -> str:
        """What the acquisition cost, in one line for the user.

        Parameters
        ----------
        shots : int
            Camera shots the acquisition holds, the direct image D's included (at least
            :attr:`captures`).

        Examples
        --------
        >>> CascadeResult(None, [], [], images=1, predicted=0, captures=1).report(33)
        '1 observation image (0 predicted) in 33 camera shots: 1 for the observations, 32 for the direct image D'
        """
        shots = max(int(shots), self.captures)
        return (f"{counted(self.images, 'observation image')} ({self.predicted} predicted) in "
                f"{counted(shots, 'camera shot')}: {self.captures} for the observations, {shots - self.captures} for "
                "the direct image D")


class _Sequence:
    """State of one decomposition's sequence (for the paper's validated linear policy)."""

    def __init__(self) -> None:
        self.trusted = False


@dataclass(frozen=True, eq=False)
class _Measured:
    """An image of the plan and its noise (None when the camera's noise is unknown)."""

    image: np.ndarray
    noise: Noise | None

    def __add__(self, other: _Measured) -> _Measured:
        noise = self.noise + other.noise if self.noise is not None and other.noise is not None else None
        return _Measured(self.image + other.image, noise)

    def __sub__(self, other: _Measured) -> _Measured:
        noise = self.noise - other.noise if self.noise is not None and other.noise is not None else None
        return _Measured(self.image - other.image, noise)


class _Plan:
    def __init__(self, recorder, calibration, prepared, kappas, order, settings, adaptive, photograph, base, prefix,
                 shared):
        self.recorder = recorder
        self.prepared = prepared
        self.kappas = kappas
        self.order = order
        self.settings = settings
        self.adaptive = adaptive
        self.photograph = photograph
        self.base = base
        self.prefix = prefix
        self.emitters = [
            Emitter(
                p.correspondence, p.direct, p.mask, calibration.response, settings.per_channel, settings.tau,
                settings.negative, p.direct_matrix, settings.complete_direct,
                p.stand_in() if settings.stand_in else None, p.spread, p.edge_direct,
            )
            for p in prepared
        ]
        # D's relative error per target: one noise source shared by every re-emission on it
        self.direct_noise = [
            None if p.direct_variance is None else
            (f"D:{prefix}-{i}", np.where(p.mask[:, :, None],
                                         np.sqrt(p.direct_variance) / np.where(p.direct > 0, p.direct, 1), 0)
             .astype(np.float32))
            for i, p in enumerate(prepared)
        ]
        # noise sources more than one image holds: their covariances must survive merging
        self.shared = set(shared) | {d[0] for d in self.direct_noise if d is not None}
        # (level, emission target) -> light emitted on the target -> the scene's response with
        # targets < level recolored: level 0 raw captures, level >= 1 recolored observations
        self.predictors = {}
        self.noise_levels: dict = {}  # (level, target) -> relative noise of its last response
        self.log: list[dict] = []
        self.clamped = 0
        self.track_predictions = False  # validate predictions even when never using them (auto order)

    def respond(self, level: int, target: int, wanted: _Measured, path: str, seq: _Sequence) -> _Measured:
        """The response to emitting ``wanted`` on ``target``, targets < ``level`` recolored.

        Level 0 is a capture (base light removed). Level ≥ 1 is a recolored observation: a
        decomposition of target ``level - 1`` under that emission, K^level captures in all —
        unless the prediction policy accepts a linear prediction from earlier emissions on the
        same target at the same level (Sec. 5's recolored prediction), which skips them all.
        """
        key = (level, target)
        predictor = self.predictors.setdefault(key, Predictor(self.prepared[target].mask))
        policy = Policy(self.adaptive.policy)
        guess = predictor.predict(wanted.image) if policy is not Policy.BRUTE or self.track_predictions else None
        band = self._band(key)
        use_guess, reason = False, ""
        if guess is not None and policy is Policy.SPAN:
            use_guess = guess.bound < band
            reason = (f"error bound {guess.bound:.2%} " + ("within" if use_guess else "above")
                      + (f" the capture's noise {band:.2%}" if band > self.adaptive.threshold
                         else f" the threshold {self.adaptive.threshold:.2%}"))
        elif guess is not None and policy is Policy.LINEAR and seq.trusted:
            use_guess, reason = True, "the sequence's prediction was validated"
        saves = self.order**level  # images a prediction at this level replaces
        if use_guess:
            assert guess is not None  # use_guess is only ever set from a guess
            self.log.append({"path": path, "target": target, "level": level, "source": "predicted",
                             "captures": [], "bound": guess.bound, "images": saves, "reason": reason})
            noise = guess.noise
            if noise is not None:  # what the light's fit leaves out, at the image's scale (Eq. 10)
                noise = noise + Noise.fresh(np.abs(guess.image) * guess.light_error.astype(np.float32), "prediction")
            return _Measured(guess.image, noise)
        if level == 0:
            emitted = None
            if wanted.noise is not None and self.base.noise is not None:
                emitted = EmittedNoise(wanted.noise, self.base.noise, self.direct_noise[target])
            done = reemit(self.recorder, self.emitters[target], wanted.image, self.base.image,
                          name=f"{self.prefix}-{path}", noise=emitted)
            self.clamped += done.clamped
            result = _Measured(done.light, done.noise)
            entry = {"path": path, "target": target, "level": 0, "source": "captured", "captures": done.names}
        else:
            result = self._recolor_lower(level, (target, wanted, seq), path)
            entry = {"path": path, "target": target, "level": level, "source": "computed", "captures": []}
        noise_level = _relative_noise(result)
        if noise_level is not None:
            self.noise_levels[key] = noise_level
        if guess is not None:
            error = relative_error(guess.image, result.image)
            own = _prediction_error(guess, result, error)  # the prediction's error, noise removed
            band = self._band(key)
            entry["prediction_error"] = error
            entry["prediction_error_without_noise"] = own
            entry["predictable"] = own < band
            if policy is Policy.LINEAR:
                seq.trusted = seq.trusted or own < band
                reason = f"prediction off by {own:.2%} beyond the noise, " + ("within" if own < band else "above")
                reason += f" the capture's noise {band:.2%}" if band > self.adaptive.threshold else \
                    f" the threshold {self.adaptive.threshold:.2%}"
        if not reason:
            reason = ("brute force" if policy is Policy.BRUTE else "no earlier light to predict from" if guess is None
                      else "the sequence's prediction is not validated yet")
        entry["reason"] = reason
        self.log.append(entry)
        predictor.add(wanted.image, result.image, result.noise)
        return result

    def _band(self, key) -> float:
        """What a prediction must beat: the threshold, or the noise of the last response at ``key``.

        A prediction whose error is within the noise its capture would carry is as good as
        the capture (Sec. 5's threshold, made noise-aware).
        """
        if not self.adaptive.noise_band:
            return self.adaptive.threshold
        return max(self.adaptive.threshold, self.noise_levels.get(key, 0.0))

    def observations(self, level: int, target: int, lighting, path: str, *, auto: bool = False) -> list[_Measured]:
        """The K observations of ``target`` under ``lighting``, targets < level recolored.

        With ``auto`` (one target, Sec. 5's last paragraph) captures continue until the linear
        prediction of the newest capture from the earlier ones is within the threshold or the
        capture's own noise (its error with the two images' noise removed), up to MAX_ORDER
        observations; ``self.order`` is then the order reached. The order the recolor uses is
        then chosen per region and channel by :mod:`engine.trust`.
        """
        seq = _Sequence()
        obs = [self.recolored(level, lighting, f"{path}.0" if path else "photograph")]
        for s in range(1, MAX_ORDER if auto else self.order):
            diff = self.settings.differences and s >= 2
            wanted = obs[s - 1] - obs[s - 2] if diff else obs[s - 1]
            sub = f"{path}.{s}" if path else f"r{s}"
            light = self.recolored(level, (target, wanted, seq), sub)
            obs.append(light + obs[s - 1] if diff else light)
            if auto and self.log[-1].get("predictable", False):
                break
        if auto:
            self.order = len(obs)
        return obs

    def recolored(self, level: int, lighting, path: str) -> _Measured:
        """The scene under ``lighting`` (None: the photograph's) with targets < level recolored."""
        if lighting is not None:
            target, wanted, seq = lighting
            return self.respond(level, target, wanted, path, seq)
        if level == 0:
            return self.photograph
        return self._recolor_lower(level, None, path)

    def _recolor_lower(self, level: int, lighting, path: str) -> _Measured:
        """Decompose target ``level - 1`` under ``lighting`` and recolor it with its fixed κ.

        With the noise known this is the noise-aware recolor (:mod:`engine.trust`): the
        photograph's noise is carried exactly (scaled as the recolor scales it), the rest of
        its predicted error as a new independent source.
        """
        t = level - 1
        obs = self.observations(t, t, lighting, path)
        stack = np.stack([o.image for o in obs]).astype(np.float32)
        noises = [o.noise for o in obs if o.noise is not None]
        if len(noises) < len(obs) or len(obs) < 2:
            image = recolor(self.prepared[t].decompose(stack), self.kappas[t])
            return _Measured(image, None)
        covariance = covariance_stack(noises, stack.shape[1:])
        # under a re-emission the brightest pixels are the projector's, not a lamp's
        result = recolor_trusted(self.prepared[t].trust(stack, covariance, lamps=lighting is None), self.kappas[t])
        photo = stack[0].astype(np.float64)
        lit = np.abs(photo) > 1e-6 * max(float(np.abs(photo).max()), 1e-30)
        scale = np.divide(result.image, photo, out=np.zeros_like(photo), where=lit)
        carried = noises[0] * scale.astype(np.float32)
        rest = np.maximum(np.square(result.sigma.astype(np.float64)) - np.square(scale) * noises[0].variance(), 0)
        noise = carried + Noise.fresh(np.sqrt(rest).astype(np.float32), "recolored")
        return _Measured(result.image, noise.merged(self.shared))


def capture_stem(target: str, mask) -> str:
    """The part of a target's capture names that names the target.

    The display name itself when it is a safe file name; otherwise (spaces, punctuation, any
    text a user may type) the session's rule for mask files, :func:`engine.session.edit.mask_name`.

    Examples
    --------
    >>> m = np.eye(3, dtype=bool)
    >>> capture_stem("right_wall", m), capture_stem("target 1", m)
    ('right_wall', 'target_1-7ea71875')
    """
    return target if NAME.fullmatch(target) and len(target) <= 64 else mask_name(target, mask_digest(mask))


# CaptureSettings is frozen: one shared default instance is safe
_DEFAULT_SETTINGS = CaptureSettings()


def acquire_cascade(
    recorder: Recorder,
    calibration: Calibration,
    targets,
    order: int,
    *,
    fixed_kappa=(),
    settings: CaptureSettings = _DEFAULT_SETTINGS,
    adaptive: Adaptive | None = None,
    photograph_pattern: np.ndarray | None = None,
    prepared=None,
    prefix: str = CAPTURE_PREFIX,
) -> CascadeResult:
    """Capture the observations of the last of several targets, earlier targets recolored.

    Parameters
    ----------
    recorder : Recorder
    calibration : Calibration
    targets : sequence of (name, (H, W) bool or float coverage)
        In cascade order; the last one's κ stays free. Any of them may be a soft mask
        (:mod:`engine.edge`): its solid pixels are re-emitted, its edge pixels blended.
    order : int or "auto"
        K, the decomposition order of every target. ``"auto"`` (one target only) captures until
        the linear prediction (Eq. 10–11) of the newest capture is within the adaptive
        threshold — the paper's suggestion for choosing the order — up to 8.
    fixed_kappa : sequence of float or (3,)
        κ of every target but the last, fixed before capture (Sec. 4).
    settings : CaptureSettings
    adaptive : Adaptive, optional
        Prediction policy and threshold (Sec. 5); None captures everything (brute force).
    photograph_pattern : (Hp, Wp, 3) float32, optional
        Projector image lighting the photograph (default black; then the photograph is the
        reference light removed from re-emissions, else a black capture is).
    prepared : sequence of PreparedTarget, optional
        D and emittable masks already measured for these targets on this rig.
    prefix : str
        Capture-name prefix.

    Returns
    -------
    CascadeResult

    Raises
    ------
    InputError
        No targets, duplicate names, overlapping targets, a wrong number of fixed κ.
    Cancelled
        Stopped on request; a rerun with the same session resumes.
    """
    auto = order == "auto"
    if auto and len(targets) != 1:
        raise InputError(f'order="auto" chooses the order of a single target; got {len(targets)} targets')
    k = MAX_ORDER if auto else check_order(order)
    if k > MAX_ORDER:
        raise InputError(f"order must be at most {MAX_ORDER}, got {k}")
    targets = [(str(n), np.asarray(m)) for n, m in targets]
    if not targets:
        raise InputError("targets is empty: give at least one (name, mask)")
    names = [n for n, _ in targets]
    if len(set(names)) != len(names):
        raise InputError(f"target names must be unique, got {names}")
    if len(fixed_kappa) != len(targets) - 1:
        raise InputError(
            f"fixed_kappa must give the κ of every target but the last ({len(targets) - 1}), got {len(fixed_kappa)}"
        )
    if prepared is not None and len(prepared) != len(targets):
        raise InputError(f"prepared must give one PreparedTarget per target ({len(targets)}), got {len(prepared)}")
    kappas = [check_kappa(kap, 3, name=f"fixed_kappa[{i}]") for i, kap in enumerate(fixed_kappa)]
    total = np.zeros(calibration.camera_resolution, np.float64)
    for _, m in targets:  # hard masks count 1 per pixel; soft masks their coverage
        m = np.asarray(m)
        total += m if m.dtype.kind == "f" else m.astype(bool)
    if (total > 1 + 1e-6).any():
        raise InputError("targets overlap: a pixel may belong to one target only "
                         "(soft masks: coverages may not sum past 1)")
    rig = recorder.rig
    identity = getattr(rig, "identity", getattr(rig, "name", calibration.rig_name))
    calibration.check_compatible(identity, tuple(rig.camera.resolution), tuple(rig.projector.resolution))
    adaptive = adaptive or Adaptive(Policy.BRUTE)
    if auto and Policy(adaptive.policy) is not Policy.BRUTE:
        raise InputError('order="auto" captures every observation; '
                         "give adaptive=None or a brute policy with a threshold")
    t_count = len(targets)
    d_cost = 0 if prepared is not None else t_count * pattern_budget(True, spread=settings.spread)
    re_emissions = (k**t_count - 1) * settings.captures_per_step()
    recorder.planned = recorder.count + 1 + (photograph_pattern is not None) + d_cost + re_emissions
    if recorder.noise is None and calibration.noise is not None:
        recorder.noise = calibration.noise
    photo_pattern = recorder.black() if photograph_pattern is None else np.asarray(photograph_pattern, np.float32)
    photo_name = f"{prefix}-photograph"
    photograph = _measure(recorder, photo_name, photo_pattern, {"kind": "photograph"})
    base_name = photo_name if photograph_pattern is None else f"{prefix}-black"
    base = photograph if photograph_pattern is None else _measure(recorder, base_name, recorder.black(),
                                                                  {"kind": "black"})
    if prepared is None:
        prepared = [
            prepare_target(recorder, calibration, m, base.image, name=f"{prefix}-{capture_stem(n, m)}",
                           spread=settings.spread)
            for n, m in targets
        ]
    plan = _Plan(recorder, calibration, list(prepared), kappas, k, settings, adaptive, photograph, base, prefix,
                 {photo_name, base_name})
    last = t_count - 1
    plan.track_predictions = auto
    measured = plan.observations(last, last, None, "", auto=auto)
    obs = np.stack([m.image for m in measured]).astype(np.float32)
    covariance = None
    noises = [m.noise for m in measured if m.noise is not None]
    if len(noises) == len(measured):
        covariance = covariance_stack(noises, obs.shape[1:])
    captured = [e for e in plan.log if e["source"] == "captured"]
    predicted = sum(e["images"] for e in plan.log if e["source"] == "predicted")
    acq_log = [{"index": 0, "source": "photograph", "captures": [f"{prefix}-photograph"]}] + [
        {"index": i + 1, **e} for i, e in enumerate(plan.log) if e["source"] != "computed"
    ]
    acquisition = Acquisition(obs, prepared[last], base.image, plan.clamped, acq_log, covariance)
    # negative noise split off only where there was some: fewer shots than planned, the count is final
    recorder.planned = recorder.count
    report(recorder.progress, recorder.count, recorder.planned, "acquisition done")
    return CascadeResult(
        acquisition=acquisition,
        targets=list(zip(names, prepared, strict=True)),
        fixed_kappa=[kap.tolist() for kap in kappas],
        images=1 + len(captured),
        predicted=predicted,
        captures=1 + sum(len(e["captures"]) for e in captured),
        log=acq_log,
    )


def _relative_noise(measured: _Measured) -> float | None:
    """``√Σ Var / ‖image‖``: the relative noise of an image (None when unknown)."""
    if measured.noise is None:
        return None
    var = measured.noise.variance()
    norm = float(np.linalg.norm(measured.image))
    return float(np.sqrt(np.sum(var, dtype=np.float64)) / norm) if var is not None and norm > 0 else 0.0


def _prediction_error(guess, result: _Measured, error: float) -> float:
    """The prediction's own relative error: the measured one with the two images' noise removed.

    ``‖p − c‖² ≈ e² + Σ Var(p − c)`` for a prediction p of a capture c; without the noises
    known, the measured error itself.
    """
    if guess.noise is None or result.noise is None:
        return error
    diff = result.noise - guess.noise
    var = diff.variance()
    norm = float(np.linalg.norm(result.image))
    if var is None or norm == 0:
        return error
    return float(np.sqrt(max(error**2 - float(np.sum(var, dtype=np.float64)) / norm**2, 0.0)))


def _measure(recorder: Recorder, name: str, pattern: np.ndarray, meta: dict) -> _Measured:
    """A capture and its noise (one source named after it)."""
    image = recorder.capture(name, pattern, meta=meta)
    var = recorder.last_variance
    return _Measured(image, None if var is None else Noise.source(name, np.sqrt(var)))


def acquire_single(
    recorder: Recorder,
    calibration: Calibration,
    target,
    order: int,
    *,
    settings: CaptureSettings = _DEFAULT_SETTINGS,
    photograph_pattern: np.ndarray | None = None,
    prepared: PreparedTarget | None = None,
    adaptive=None,
    name: str = "target",
) -> Acquisition:
    """Capture the observations of one target (Sec. 3.3).

    Parameters
    ----------
    recorder : Recorder
        The rig, session, progress and cancellation.
    calibration : Calibration
        Of this rig (checked).
    target : (H, W) bool
        The painted target in camera pixels.
    order : int
        K: the photograph plus K-1 re-emissions.
    settings : CaptureSettings
    photograph_pattern : (Hp, Wp, 3) float32, optional
        What the projector shows for the photograph (e.g. a flood, the paper's Fig. 7-8
        lighting); default black. When given, re-emissions are shown without it and a
        projector-black capture is the light removed.
    prepared : PreparedTarget, optional
        D and the emittable mask from an earlier :func:`prepare_target` of the same target
        on the same rig; measured now when None.
    adaptive : engine.acquire.predict.Adaptive, optional
        Predict re-emissions instead of capturing them (Sec. 5).
    name : str
        Capture-name prefix.

    Returns
    -------
    Acquisition

    Raises
    ------
    InputError
        Bad order, a calibration of another rig, a target the projector cannot reach.
    Cancelled
        Stopped on request; captures so far are in the session and a rerun resumes.

    Notes
    -----
    The one-target case of :func:`acquire_cascade`. Costs 1
    photograph (+1 black with ``photograph_pattern``), ``pattern_budget`` captures for D,
    and K-1 re-emissions of ``settings.captures_per_step()`` captures each.
    """
    result = acquire_cascade(
        recorder,
        calibration,
        [(name, target)],
        order,
        settings=settings,
        adaptive=adaptive,
        photograph_pattern=photograph_pattern,
        prepared=None if prepared is None else [prepared],
        prefix=name,
    )
    return result.acquisition
