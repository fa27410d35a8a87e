"""Camera and projector backends behind two small protocols (see ``devices.base``).

``open_rig("virtual:cornell", ideal=True)`` opens a rig by name; ``available()`` lists what can
be opened on this machine and why the others can't.
"""

from devices.base import Camera, Frame, Projector, Rig
from devices.registry import available, available_projectors, open_rig

__all__ = ["Camera", "Frame", "Projector", "Rig", "available", "available_projectors", "open_rig"]
