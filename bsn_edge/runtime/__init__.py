"""The edge runtime: sources, the fused model's engine, the loop, the send cycle, the overlay."""

from bsn_edge.runtime.engine import Engine, ModelInfo
from bsn_edge.runtime.loop import RuntimeConfig, run
from bsn_edge.runtime.sources import open_source

__all__ = ["Engine", "ModelInfo", "RuntimeConfig", "open_source", "run"]
