"""GenICam machine-vision cameras through harvesters: not implemented yet (probe only).

A GenICam backend needs a GenTL producer (a vendor ``.cti`` file) and the ``harvesters``
package. The plan, from the library's documentation (not yet written or tested): ``Harvester()``,
``add_file(cti)``, ``update()``, ``create(...)``; switch ``ExposureAuto``/``GainAuto`` off and set
``ExposureTime`` (µs) and a linear ``PixelFormat`` (Mono16/BayerRG16) on
``ia.remote_device.node_map``; ``ia.start()``; ``with ia.fetch(timeout=...) as buf`` copy
``buf.payload.components[0].data``; ``stop(); destroy(); reset()``. Until then, use the
``hotfolder`` backend with the vendor's acquisition software saving 16-bit TIFFs.
"""

from __future__ import annotations

import importlib.util

from devices.registry import Availability
from engine.errors import DeviceError

__all__ = ["open_rig", "probe"]

_WHY = "the harvesters (GenICam) backend is not implemented yet; use hotfolder: with the vendor's software saving 16-bit TIFFs"


def probe() -> list[Availability]:
    """Say why a GenICam rig cannot be opened here.

    Examples
    --------
    >>> probe()[0].ok
    False
    """
    installed = importlib.util.find_spec("harvesters") is not None
    library = "harvesters is installed" if installed else "harvesters is not installed"
    return [Availability("harvesters:", False, f"{_WHY} ({library})")]


def open_rig(arg: str = "", **options):
    """Refuse with the reason: the GenICam backend does not exist yet.

    Raises
    ------
    DeviceError
        Always.
    """
    raise DeviceError(_WHY)
