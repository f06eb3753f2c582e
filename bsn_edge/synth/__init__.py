"""A synthetic driving world: RGB, exact depth, semantics, poses and true blind spots.

>>> from bsn_edge.synth import SynthConfig, write_clip
>>> write_clip(SynthConfig(frames=50, style="town", seed=0), "clips/town0")  # doctest: +SKIP
"""

from bsn_edge.synth.boxes import Agents, Boxes
from bsn_edge.synth.clip import Clip, make_clip, render_frames, write_clip
from bsn_edge.synth.config import SynthConfig
from bsn_edge.synth.layout import RoadLayout
from bsn_edge.synth.render import Frame, Renderer
from bsn_edge.synth.style import STYLES, get_style
from bsn_edge.synth.world import Look, World

__all__ = [
    "STYLES",
    "Agents",
    "Boxes",
    "Clip",
    "Frame",
    "Look",
    "Renderer",
    "RoadLayout",
    "SynthConfig",
    "World",
    "get_style",
    "make_clip",
    "render_frames",
    "write_clip",
]
