"""Model cards for tests: what an untrained model would carry."""

from bsn_edge.camera import Intrinsics
from bsn_edge.card import ModelCard
from bsn_edge.networks import create_model, describe


def card_for(size: tuple[int, int], variant: str = "small-light", threshold: float | None = 0.5,
             hfov_deg: float = 80.0) -> ModelCard:
    h, w = size
    return describe(variant, create_model(variant), Intrinsics.from_fov(w, h, hfov_deg), threshold, "test")
