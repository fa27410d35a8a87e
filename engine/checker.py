"""The ColorChecker Classic in a photograph: where its 24 patches are and what they reflect.

A chart is placed by four corners — the outer corners of its patch area, in the order
dark skin (top left), bluish green (top right), black (bottom right), white (bottom left) —
found by colour-checker-detection's segmentation detector, or dragged by hand (always
possible: the detector needs the chart reasonably large, sharp and unoccluded). Patches are
the 6 × 4 cells of that quadrilateral in perspective; each is sampled on its central part.

Reference reflectances come from colour-science: the published spectral reflectances of
the chart (N. Ohta's measurements) integrated over a camera's spectral sensitivities under an
illuminant, which gives the per-channel albedo that camera sees.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import cache

import numpy as np

from engine.checks import check_float_image, check_mask
from engine.colour import colour_science
from engine.errors import InputError

__all__ = [
    "COLUMNS",
    "PATCHES",
    "ROWS",
    "Checker",
    "NoChart",
    "checker_from_corners",
    "detect_checker",
    "patch_names",
    "reference_reflectances",
    "sample_patches",
]



class NoChart(InputError):
    """No chart could be found automatically; placing its four corners by hand still works."""


COLUMNS, ROWS = 6, 4
PATCHES = COLUMNS * ROWS
#: Spectral reflectances of the ColorChecker Classic in colour-science.
REFLECTANCE_DATA = "ColorChecker N Ohta"
#: Default camera channels: measured sensitivities of a DSLR's raw channels (colour-science).
#: The virtual rig's camera has these channels.
SENSITIVITIES = "Nikon 5100 (NPL)"
ILLUMINANT = "D65"


def patch_names() -> list[str]:
    """The 24 patch names in chart order (row by row from dark skin to black).

    Examples
    --------
    >>> names = patch_names()
    >>> names[0], names[18], names[23]
    ('dark skin', 'white 9.5 (.05 D)', 'black 2 (1.5 D)')
    """
    return list(colour_science().SDS_COLOURCHECKERS[REFLECTANCE_DATA])


@cache
def _reflectances(sensitivities: str, illuminant: str) -> np.ndarray:
    colour = colour_science()
    try:
        cam = colour.MSDS_CAMERA_SENSITIVITIES[sensitivities]
    except KeyError:
        raise InputError(f"unknown camera sensitivities {sensitivities!r}; colour-science has "
                         f"{sorted(colour.MSDS_CAMERA_SENSITIVITIES)}") from None
    try:
        light = colour.SDS_ILLUMINANTS[illuminant]
    except KeyError:
        raise InputError(f"unknown illuminant {illuminant!r}; try 'D65', 'D50', 'A' or 'E'") from None
    shape = cam.shape
    s = np.asarray(cam.values, np.float64)
    e = np.asarray(light.copy().align(shape).values, np.float64)
    r = np.array([sd.copy().align(shape).values for sd in colour.SDS_COLOURCHECKERS[REFLECTANCE_DATA].values()])
    out = (r * e[None, :]) @ s / (e @ s)[None, :]
    out.setflags(write=False)
    return out


def reference_reflectances(sensitivities: str = SENSITIVITIES, illuminant: str = ILLUMINANT) -> np.ndarray:
    """Per-channel albedo of the 24 patches as a camera sees them.

    Parameters
    ----------
    sensitivities : str
        A camera in ``colour.MSDS_CAMERA_SENSITIVITIES``. The default's channels are those of
        the virtual rig; for another camera pass its own if colour-science has them.
    illuminant : str
        A spectral illuminant in ``colour.SDS_ILLUMINANTS`` weighting the integration.

    Returns
    -------
    (24, 3) float64, read-only
        ``ρ_c = ∫ R(λ) S_c(λ) E(λ) dλ / ∫ S_c(λ) E(λ) dλ`` for each patch and channel c: the
        albedo a surface of spectral reflectance R has in channel c. All in (0, 1).

    Examples
    --------
    >>> rho = reference_reflectances()
    >>> rho.shape, bool(rho.min() > 0 and rho.max() < 1)
    ((24, 3), True)
    >>> np.round(rho[18], 2).tolist()        # the white patch is neutral
    [0.89, 0.89, 0.88]
    """
    return _reflectances(str(sensitivities), str(illuminant))


@dataclass(frozen=True)
class Checker:
    """A ColorChecker placed in a camera image.

    Attributes
    ----------
    corners : (4, 2) float64
        ``(x, y)`` pixel coordinates (pixel centres at integers) of the patch area's outer
        corners: dark skin's, bluish green's, black's and white's.
    shape : (H, W)
        The image it was placed in.
    source : str
        ``"detected"`` or ``"manual"``.
    """

    corners: np.ndarray
    shape: tuple[int, int]
    source: str = "manual"

    def homography(self) -> np.ndarray:
        """(3, 3): chart coordinates ``(u, v)`` (u in 0..6 across, v in 0..4 down) → pixels."""
        import cv2

        chart = np.array([[0, 0], [COLUMNS, 0], [COLUMNS, ROWS], [0, ROWS]], np.float32)
        return cv2.getPerspectiveTransform(chart, self.corners.astype(np.float32)).astype(np.float64)

    def centres(self) -> np.ndarray:
        """(24, 2) ``(x, y)`` of each patch's centre, in chart order."""
        v, u = np.divmod(np.arange(PATCHES), COLUMNS)
        return _apply(self.homography(), np.stack([u + 0.5, v + 0.5], 1))

    def labels(self, *, fraction: float = 0.5) -> np.ndarray:
        """(H, W) int8: the patch (0–23) whose cell's central ``fraction`` (per side) holds the
        pixel's centre, −1 elsewhere.

        The default keeps clear of the chart's black gaps and of blur at patch edges. Only the
        chart's bounding box is visited, so a chart in a large photograph costs little.
        """
        if not 0 < fraction <= 1:
            raise InputError(f"fraction must be in (0, 1], got {fraction!r}")
        h, w = self.shape
        out = np.full((h, w), -1, np.int8)
        x0, y0 = np.maximum(np.floor(self.corners.min(axis=0)).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(self.corners.max(axis=0)).astype(int) + 1, [w, h])
        if x1 <= x0 or y1 <= y0:
            return out
        yy, xx = np.mgrid[y0:y1, x0:x1]
        uv = _apply(np.linalg.inv(self.homography()), np.stack([xx.ravel(), yy.ravel()], 1).astype(np.float64))
        cell = np.floor(uv)
        inner = np.abs(uv - cell - 0.5) < fraction / 2  # pixel centre in the cell's central part
        ok = inner.all(axis=1) & (cell[:, 0] >= 0) & (cell[:, 0] < COLUMNS) & (cell[:, 1] >= 0) & (cell[:, 1] < ROWS)
        index = np.where(ok, cell[:, 1] * COLUMNS + cell[:, 0], -1).astype(np.int8)
        out[y0:y1, x0:x1] = index.reshape(y1 - y0, x1 - x0)
        return out

    def patch_masks(self, *, fraction: float = 0.5) -> np.ndarray:
        """(24, H, W) bool: one mask per patch (see :meth:`labels`; for small images)."""
        return self.labels(fraction=fraction)[None] == np.arange(PATCHES, dtype=np.int8)[:, None, None]

    def mask(self, *, fraction: float = 0.5) -> np.ndarray:
        """(H, W) bool: every patch's sampled pixels (a target for measuring D on the chart)."""
        return self.labels(fraction=fraction) >= 0


def checker_from_corners(corners, shape) -> Checker:
    """Place a chart by hand.

    Parameters
    ----------
    corners : (4, 2) float
        ``(x, y)`` of the patch area's corners at dark skin, bluish green, black and white.
    shape : (H, W)
        Image size.

    Returns
    -------
    Checker

    Raises
    ------
    InputError
        Not four finite points, a corner outside the image, or a quadrilateral that is not
        convex in that order (corners crossed or given in the wrong order).

    Examples
    --------
    >>> c = checker_from_corners([[10, 10], [70, 10], [70, 50], [10, 50]], (60, 80))
    >>> np.round(c.centres()[0], 2).tolist(), int(c.patch_masks()[0].sum())
    ([15.0, 15.0], 25)
    """
    pts = np.asarray(corners, np.float64)
    if pts.shape != (4, 2) or not np.all(np.isfinite(pts)):
        raise InputError(f"corners must be 4 points (x, y), got {np.asarray(corners).tolist()!r:.120}")
    try:
        h, w = (int(v) for v in shape)
    except (TypeError, ValueError):
        raise InputError(f"shape must be (H, W), got {shape!r}") from None
    outside = [k for k, (x, y) in enumerate(pts) if not (-0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5)]
    if outside:
        raise InputError(f"checker corner(s) {outside} lie outside the {w}×{h} image: {pts[outside].tolist()}")
    edges = np.roll(pts, -1, axis=0) - pts
    turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    if not (np.all(turns > 0) or np.all(turns < 0)):
        raise InputError("the four checker corners do not form a convex quadrilateral in the order dark skin, "
                         "bluish green, black, white; place them again in that order")
    return Checker(pts, (h, w), "manual")


def detect_checker(image) -> Checker:
    """Find a ColorChecker Classic in a linear photograph.

    Parameters
    ----------
    image : (H, W, 3) float, linear radiance

    Returns
    -------
    Checker
        ``source == "detected"``; corners oriented by the chart's colours.

    Raises
    ------
    NoChart
        No chart found, or too small to sample (the message says to place its four corners by hand).
    InputError
        Not an RGB image.

    Notes
    -----
    colour-checker-detection's segmentation detector finds the patch area, run on the image
    (area-averaged down to the detector's 1440-px working width first: a 24 MP photograph
    takes seconds, not a minute) scaled so its 90th percentile is 1 (it thresholds sRGB-encoded values; a lamp in view
    would make a 99th-percentile scale too dark). Its corners come back from its resampled
    working copy to this image's pixels; of the chart's four orientations the one whose patch
    colours fit the reference reflectances best (after a per-channel scale, so a coloured
    light does not matter) is kept.
    """
    img = check_float_image("image", image, ndim=3)
    if img.shape[2] != 3:
        raise InputError(f"image must have 3 channels, got shape {img.shape}")
    import cv2

    h, w = img.shape[:2]
    ccd = _detector()
    work_w = int(ccd.SETTINGS_SEGMENTATION_COLORCHECKER_CLASSIC["working_width"])
    small: np.ndarray = img.astype(np.float32, copy=False)
    if w > work_w:  # area-average a large photograph down to the detector's working width first
        small = cv2.resize(small, (work_w, int(h * work_w / w)), interpolation=cv2.INTER_AREA)
    level = float(np.percentile(small, 90))
    if level <= 0:
        raise InputError("the image is black: no colour checker to find")
    scaled = np.clip(small / level, 0.0, 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # the segmenter encodes to sRGB before resampling (resampling linear values first
        # rings at the patch edges and loses most patches on small images)
        found = ccd.segmenter_default(scaled, additional_data=True)
    rectangles = found.rectangles
    if len(rectangles) == 0:
        raise NoChart("no ColorChecker found in the photograph: place its four corners by hand "
                         "(dark skin, bluish green, black, white)")
    work_h = float(int(h * work_w / w))

    def to_image(points):  # the detector's working pixels → this image's
        points = np.asarray(points, np.float64).reshape(-1, 2)
        return np.c_[(points[:, 0] + 0.5) * w / work_w - 0.5, (points[:, 1] + 0.5) * h / work_h - 0.5]

    rough = _oriented(img, np.clip(to_image(rectangles[0]), -0.5, [w - 0.5, h - 0.5]))
    swatches = np.asarray(found.swatches, np.float64)
    centres = to_image(swatches.mean(axis=1)) if len(swatches) else np.zeros((0, 2))
    return _refined(rough, centres)


@cache
def _detector():
    """colour-checker-detection, imported once, leaving numpy's print options as they were."""
    colour_science()
    printing = np.get_printoptions()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import colour_checker_detection
    except ImportError:
        raise NoChart(
            "automatic colour-checker detection needs colour-checker-detection "
            "(pip install --no-deps colour-checker-detection); place the chart's four corners by hand instead"
        ) from None
    finally:
        np.set_printoptions(**printing)
    return colour_checker_detection


def _refined(rough: Checker, centres: np.ndarray) -> Checker:
    """Fit the perspective to the detected swatch centres (the detector's own quadrilateral
    is a rotated rectangle around them, which misses perspective).

    Each centre is given the cell of ``rough`` it falls in; with at least 8 cells found, a
    homography from cell centres to swatch centres replaces the rectangle.
    """
    import cv2

    if len(centres) == 0:
        return rough
    uv = _apply(np.linalg.inv(rough.homography()), centres)
    cell = np.floor(uv).astype(int)
    inside = (cell[:, 0] >= 0) & (cell[:, 0] < COLUMNS) & (cell[:, 1] >= 0) & (cell[:, 1] < ROWS)
    index = cell[:, 1] * COLUMNS + cell[:, 0]
    chart, seen = [], []
    for i in np.unique(index[inside]):
        pick = inside & (index == i)
        chart.append([i % COLUMNS + 0.5, i // COLUMNS + 0.5])
        seen.append(centres[pick].mean(axis=0))
    if len(chart) < 8:
        return rough
    hom, _ = cv2.findHomography(np.asarray(chart, np.float64), np.asarray(seen, np.float64), 0)
    if hom is None:
        return rough
    corners = _apply(hom, np.array([[0, 0], [COLUMNS, 0], [COLUMNS, ROWS], [0, ROWS]], np.float64))
    h, w = rough.shape
    if not np.all(np.isfinite(corners)):
        return rough
    return Checker(np.clip(corners, -0.5, [w - 0.5, h - 0.5]), rough.shape, "detected")


def _oriented(image: np.ndarray, corners: np.ndarray) -> Checker:
    """The corner order (of 4 rotations × 2 windings) whose patches best fit the reference."""
    rho = reference_reflectances()
    best, best_err = None, np.inf
    for order in ([0, 1, 2, 3], [0, 3, 2, 1]):
        for shift in range(4):
            c = Checker(np.roll(corners[order], shift, axis=0), image.shape[:2], "detected")
            means = _point_means(image, c)
            scale = (means * rho).sum(axis=0) / (rho**2).sum(axis=0)
            err = float(np.sum((means / np.maximum(scale, 1e-30) - rho) ** 2))
            if err < best_err:
                best, best_err = c, err
    if best is None:
        raise NoChart("a ColorChecker was found but its patches are too small to sample: move the camera "
                         "closer or place the four corners by hand")
    return best


def _point_means(image: np.ndarray, checker: Checker, *, points: int = 5, fraction: float = 0.5) -> np.ndarray:
    """(24, C): each patch's mean over a ``points × points`` grid in its central part (nearest
    pixels): enough to tell the chart's orientation, at any image size."""
    step = (np.arange(points) + 0.5) / points * fraction + (0.5 - fraction / 2)
    du, dv = np.meshgrid(step, step)
    v, u = np.divmod(np.arange(PATCHES), COLUMNS)
    uv = np.stack([(u[:, None] + du.ravel()).ravel(), (v[:, None] + dv.ravel()).ravel()], 1)
    xy = np.rint(_apply(checker.homography(), uv)).astype(np.intp)
    h, w = checker.shape
    xs, ys = np.clip(xy[:, 0], 0, w - 1), np.clip(xy[:, 1], 0, h - 1)
    return image[ys, xs].astype(np.float64).reshape(PATCHES, points * points, -1).mean(axis=1)


def sample_patches(image, checker: Checker, *, fraction: float = 0.5, valid=None) -> tuple[np.ndarray, np.ndarray]:
    """Mean value of each patch.

    Parameters
    ----------
    image : (H, W, C) float
        Any per-pixel quantity: the photograph, or the direct image D.
    checker : Checker
    fraction : float
        Central part of each patch cell sampled, see :meth:`Checker.labels`.
    valid : (H, W) bool, optional
        Pixels that may be used (e.g. where D was measured).

    Returns
    -------
    means : (24, C) float64
        NaN for a patch without a usable pixel.
    counts : (24,) int
        Pixels averaged per patch.
    """
    img = check_float_image("image", image, ndim=3)
    if img.shape[:2] != tuple(checker.shape):
        raise InputError(f"image is {img.shape[:2]} but the checker was placed in a {tuple(checker.shape)} image")
    labels = checker.labels(fraction=fraction)
    if valid is not None:
        labels = np.where(check_mask("valid", valid, img.shape[:2]), labels, -1)
    ys, xs = np.nonzero(labels >= 0)
    index = labels[ys, xs].astype(np.intp)
    counts = np.bincount(index, minlength=PATCHES)
    values = img[ys, xs].astype(np.float64)
    sums = np.stack([np.bincount(index, weights=values[:, c], minlength=PATCHES) for c in range(img.shape[2])], 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], np.nan)
    return means, counts


def _apply(hom: np.ndarray, pts: np.ndarray) -> np.ndarray:
    p = np.c_[pts, np.ones(len(pts))] @ hom.T
    return p[:, :2] / p[:, 2:3]
