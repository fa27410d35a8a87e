"""The canvas views: one table, :data:`VIEWS`, says everything about each. Qt-free.

Each :class:`ViewSpec` gives a view's name, menu label, toolbar label, shortcut, how it renders
a frame and reads out a pixel, what it needs (a decomposition, ground truth) and what is shown
instead until then. The View menu, the toolbar, the shortcuts, the preview's choice of what
can be shown and the fallbacks all read this table: adding a view is adding a member to
:class:`CanvasView` and an entry (with its render function) here — docs/ui.md says how.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from app.model.display import MAGNITUDE_MAP, SIGNED_MAP, false_colour, luminance, recolor_rgb32, robust_max, to_rgb32
from app.model.render import Detail, PreviewFrame, Request, ScaleBar, ViewRenderer
from engine.acquire.predict import relative_error
from engine.recolor import area_average, recolor, recolor_variance


class CanvasView(StrEnum):
    """Canvas views, by name (the ids of :data:`VIEWS`)."""

    RECOLORED = "recolored"
    ORIGINAL = "original"
    SPLIT = "split"
    DIFFERENCE = "difference"
    COMPONENTS = "components"
    TRUTH = "truth"
    ERROR = "error"
    NOISE = "noise"


class Need(StrEnum):
    """What a view needs besides the photograph (:meth:`ViewRenderer.has`, :meth:`PreviewController.available`)."""

    DECOMPOSITION = "decomposition"  # an acquisition
    TRUTH = "truth"  # ground truth (virtual rigs)


#: What the user can do about each missing :class:`Need` (a disabled view or action says it).
NEED_HINTS = {
    Need.DECOMPOSITION: "acquire a target first (Rig ▸ Acquire…)",
    Need.TRUTH: "only a simulated rig's scene has a ground truth",
}


#: What the recolored views say while nothing is measured (drawn as a banner over the picture).
NAIVE_BANNER = ("Naive preview: each target's pixels are multiplied by its κ. Interreflections follow only once "
                "the scene is captured with a rig (Rig ▸ Calibrate…, then Rig ▸ Acquire…).")


@dataclass(frozen=True)
class ViewSpec:
    """One canvas view: everything the app needs to know about it, in one place.

    Attributes
    ----------
    view : CanvasView
        Its name; the View menu action is ``view_<name>`` (docs/ui.md).
    label : str
        Menu text (``&`` marks the mnemonic); ``short`` is the toolbar's.
    shortcut : str
        Key sequence that shows it.
    render : callable
        ``render(renderer, request) -> PreviewFrame``.
    readout : callable or None
        ``readout(renderer, x, y, kappa, edit) -> (label, rgb)`` for the status bar.
    needs : frozenset of Need
        What it cannot do without; the view is offered only when all are there, and
        ``fallback`` is shown instead meanwhile.
    edit : bool
        It shows the whole edit (every target's mask and κ), so requests carry it.
    detail : bool
        Zoomed in, it sharpens to full resolution (:meth:`ViewRenderer.render_detail`).
    """

    view: CanvasView
    label: str
    short: str
    shortcut: str
    render: Callable[[ViewRenderer, Request], PreviewFrame]
    readout: Callable | None = None
    needs: frozenset = frozenset()
    fallback: CanvasView | None = None
    edit: bool = False
    detail: bool = False
    tip: str = ""


def _render_original(r: ViewRenderer, req: Request) -> PreviewFrame:
    return PreviewFrame(CanvasView.ORIGINAL, to_rgb32(r.small_photo, exposure=req.exposure), r.shape,
                        linear=r.small_photo)


def _recolored_pixels(r: ViewRenderer, req: Request) -> tuple[np.ndarray, str, np.ndarray | None]:
    if r.pack is None:
        return to_rgb32(r.naive_small(req.edit), exposure=req.exposure), NAIVE_BANNER, None
    if r.exact(req):  # the noise-aware recolor export writes, area-averaged
        lin = r.recolored_small(req.kappa)
        return to_rgb32(lin, exposure=req.exposure), "", lin
    # the hot path: recolor and display conversion fused, no float image in between
    return recolor_rgb32(r.pack.decomposition, req.kappa, exposure=req.exposure), "", None


def _render_recolored(r: ViewRenderer, req: Request) -> PreviewFrame:
    pixels, banner, lin = _recolored_pixels(r, req)
    return PreviewFrame(CanvasView.RECOLORED, pixels, r.shape, linear=lin, banner=banner)


def _render_split(r: ViewRenderer, req: Request) -> PreviewFrame:
    pixels, banner, lin = _recolored_pixels(r, req)
    return PreviewFrame(CanvasView.SPLIT, pixels, r.shape, second=to_rgb32(r.small_photo, exposure=req.exposure),
                        linear=lin, banner=banner)


def _render_difference(r: ViewRenderer, req: Request) -> PreviewFrame:
    lin = r.recolored_small(req.kappa, fast=req.fast) if r.pack is not None else r.naive_small(req.edit)
    delta = luminance(lin) - luminance(r.small_photo)
    s = robust_max(delta)
    return PreviewFrame(CanvasView.DIFFERENCE, false_colour(delta, -s, s, SIGNED_MAP), r.shape, linear=lin,
                        scale=ScaleBar(-s, s, SIGNED_MAP, "Δ luminance (recolored − original)"),
                        banner="" if r.pack is not None else NAIVE_BANNER)


def _render_components(r: ViewRenderer, req: Request) -> PreviewFrame:
    pixels, tiles = r.component_tiles(req.grid, req.exposure)
    rows, cols = req.grid
    return PreviewFrame(CanvasView.COMPONENTS, pixels, (rows * r.shape[0], cols * r.shape[1]), tiles=tiles,
                        note="inside the target R^i L_d, outside C R^(i-1) L_d (first tile: L_d and L̄_d)")


def _render_truth(r: ViewRenderer, req: Request) -> PreviewFrame:
    small = area_average(r.truth_full(req.edit), r.factor)
    return PreviewFrame(CanvasView.TRUTH, to_rgb32(small, exposure=req.exposure), r.shape, linear=small,
                        note="ground truth")


def _render_error(r: ViewRenderer, req: Request) -> PreviewFrame:
    truth_small = area_average(r.truth_full(req.edit), r.factor)
    lin = r.recolored_small(req.kappa, fast=req.fast)
    err = np.abs(luminance(lin) - luminance(truth_small))
    s = robust_max(err)
    note = f"relative error {100 * relative_error(lin, truth_small):.2f} %"
    if r.emitters is not None and r.emitters.any():
        surfaces = area_average(r.emitters.astype(np.float32), r.factor) == 0
        note += f", {100 * relative_error(lin, truth_small, surfaces):.2f} % without the lamp"
    return PreviewFrame(CanvasView.ERROR, false_colour(err, 0.0, s, MAGNITUDE_MAP), r.shape, linear=lin,
                        scale=ScaleBar(0.0, s, MAGNITUDE_MAP, "|recolored − ground truth| (luminance)"),
                        note=note + " (preview resolution)")


#: What the noise view says when the acquisition carries no noise model.
NO_NOISE_BANNER = ("This acquisition carries no noise model (captured before the camera's noise was measured): "
                   "recalibrate and capture again to see the predicted error.")


def _render_noise(r: ViewRenderer, req: Request) -> PreviewFrame:
    d = r.pack.decomposition
    if r.exact(req):  # the σ of the noise-aware recolor shown (its own prediction: noise and remaining bias)
        done = r.trusted_recolor(req.kappa)
        sigma, image, target = area_average(done.sigma, r.factor), done.image, r.trusted.target
        sigma_full, which = done.sigma, " (noise-aware recolor)"
    elif d.covariance is None:
        return PreviewFrame(CanvasView.NOISE, to_rgb32(r.small_photo, exposure=req.exposure), r.shape,
                            banner=NO_NOISE_BANNER)
    else:
        sigma = np.sqrt(recolor_variance(d, req.kappa))
        image, target, sigma_full, which = recolor(d, req.kappa), d.target, sigma, ""
    shown = np.sqrt(np.mean(np.square(sigma), axis=-1))  # RMS over the channels
    s = robust_max(shown)
    note = ""
    if target.any():
        value = float(np.abs(image[target]).mean())
        mean = float(sigma_full[target].mean())
        note = (f"predicted σ on the target{which}: mean {mean:.3g} "
                f"({100 * mean / max(value, 1e-30):.2f} % of its value)")
    return PreviewFrame(CanvasView.NOISE, false_colour(shown, 0.0, s, MAGNITUDE_MAP), r.shape, linear=sigma,
                        scale=ScaleBar(0.0, s, MAGNITUDE_MAP, "predicted σ of the recolored image (RMS over R, G, B)"),
                        note=note)


def _read_original(r: ViewRenderer, x: int, y: int, kappa, edit):
    return "original", r.photograph[y, x]


def _read_recolored(r: ViewRenderer, x: int, y: int, kappa, edit):
    if r.decomposition is None:
        return "naive recolor", r.naive_pixel(x, y, edit)
    return "recolored", r.pixel(x, y, kappa)


def _read_difference(r: ViewRenderer, x: int, y: int, kappa, edit):
    return "recolored − original", _read_recolored(r, x, y, kappa, edit)[1] - r.photograph[y, x]


def _read_truth(r: ViewRenderer, x: int, y: int, kappa, edit):
    return "ground truth", r.truth_full(edit)[y, x]


def _read_error(r: ViewRenderer, x: int, y: int, kappa, edit):
    return "recolored − truth", r.pixel(x, y, kappa) - r.truth_full(edit)[y, x]


def _read_noise(r: ViewRenderer, x: int, y: int, kappa, edit):
    if r.trusted is not None and (done := r.cached_trusted(kappa)) is not None:
        return "predicted σ (noise-aware)", done.sigma[y, x]
    d = r.decomposition.crop(y, y + 1, x, x + 1)
    if d.covariance is None:
        return "recolored (no noise model)", r.pixel(x, y, kappa)
    return "predicted σ", np.sqrt(recolor_variance(d, kappa))[0, 0]


_D, _T = Need.DECOMPOSITION, Need.TRUTH

#: Every canvas view, in menu and toolbar order.
VIEWS: tuple[ViewSpec, ...] = (
    ViewSpec(CanvasView.RECOLORED, "&Recolored", "Recolored", "1", _render_recolored, _read_recolored,
             edit=True, detail=True, tip="The edit: measured interreflections once acquired, a naive recolor before"),
    ViewSpec(CanvasView.ORIGINAL, "&Original", "Original", "2", _render_original, _read_original, detail=True,
             tip="The photograph as captured"),
    ViewSpec(CanvasView.SPLIT, "&Split Before/After", "Split", "3", _render_split, _read_recolored, edit=True,
             detail=True, tip="Recolored left of the divider, original right; drag the divider"),
    ViewSpec(CanvasView.DIFFERENCE, "&Difference", "Difference", "4", _render_difference, _read_difference,
             edit=True, tip="Luminance change, false colour with a scale bar"),
    ViewSpec(CanvasView.COMPONENTS, "Interaction &Components", "Components", "5", _render_components, None,
             needs=frozenset({_D}), fallback=CanvasView.ORIGINAL,
             tip="The interaction components R^i L_d (the paper's Fig. 6 layout)"),
    ViewSpec(CanvasView.TRUTH, "&Ground Truth", "Truth", "6", _render_truth, _read_truth, needs=frozenset({_T}),
             fallback=CanvasView.ORIGINAL, edit=True, tip="The virtual rig's exact result of this edit"),
    ViewSpec(CanvasView.ERROR, "&Error vs Ground Truth", "Error", "7", _render_error, _read_error,
             needs=frozenset({_D, _T}), fallback=CanvasView.TRUTH, edit=True,
             tip="|recolored − ground truth| and the relative error"),
    ViewSpec(CanvasView.NOISE, "Predicted &Noise (σ)", "Noise σ", "8", _render_noise, _read_noise,
             needs=frozenset({_D}), fallback=CanvasView.ORIGINAL,
             tip="Predicted standard deviation of the recolored image from the camera's noise: where the edit is "
                 "unreliable"),
)
VIEW_SPECS: dict[CanvasView, ViewSpec] = {spec.view: spec for spec in VIEWS}


def has(renderer: ViewRenderer, need: Need) -> bool:
    """Whether ``renderer`` has what ``need`` names."""
    return {Need.DECOMPOSITION: renderer.decomposition is not None, Need.TRUTH: renderer.truth is not None}[need]


def shown(renderer: ViewRenderer, view: str) -> ViewSpec:
    """The view actually shown for ``view``: itself, or its fallback while something it needs is missing."""
    spec = VIEW_SPECS[CanvasView(view)]
    while not all(has(renderer, n) for n in spec.needs):
        spec = VIEW_SPECS[spec.fallback]
    return spec


def render(renderer: ViewRenderer, request: Request) -> PreviewFrame:
    """The frame of ``request`` (on the preview worker)."""
    if not renderer.prepared:
        renderer.prepare()
    return shown(renderer, request.view).render(renderer, request)


def render_detail(renderer: ViewRenderer, request: Request, region: tuple[int, int, int, int]) -> Detail | None:
    """Full-resolution pixels of ``region`` = (y0, y1, x0, x1) in ``request``'s view, or None.

    None where the preview already is full resolution or the view has no detail
    (``ViewSpec.detail``: the diagnostic false-colour views keep the preview's scale).
    """
    spec = shown(renderer, request.view)
    if not spec.detail:
        return None
    return renderer.detail(request, region, original=spec.view == CanvasView.ORIGINAL,
                           split=spec.view == CanvasView.SPLIT)


def readout(renderer: ViewRenderer, view: str, x: int, y: int, kappa, edit=()) -> tuple[str, np.ndarray] | None:
    """Exact linear value at camera pixel (x, y) in ``view`` for the status bar, or None outside.

    Recolored values come from the full-resolution decomposition at that pixel (same maths as
    :func:`engine.recolor.recolor`).
    """
    h, w = renderer.shape
    spec = shown(renderer, view)
    if not (0 <= x < w and 0 <= y < h) or spec.readout is None:
        return None
    return spec.readout(renderer, x, y, kappa, edit)
