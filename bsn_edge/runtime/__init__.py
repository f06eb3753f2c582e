"""The edge runtime: sources, the verified model engine, the loop, the send cycle, the overlay.

Nothing here imports torch, onnx or onnxruntime's quantization tools: this is what runs on the car.
"""

from bsn_edge.runtime.engine import Engine, ModelError
from bsn_edge.runtime.live_source import Reconnect
from bsn_edge.runtime.loop import run
from bsn_edge.runtime.settings import RuntimeConfig
from bsn_edge.runtime.sources import open_source

__all__ = ["Engine", "ModelError", "Reconnect", "RuntimeConfig", "open_source", "run"]
