"""One small exported model and one short synthetic clip, shared by the runtime tests."""

import pytest

from bsn_edge.synth import SynthConfig, write_clip

SIZE = (128, 256)


@pytest.fixture(scope="session")
def setup(tmp_path_factory, small_light_onnx):
    """(an untrained small-light model exported at 128x256, a 15-frame 96x192 clip with its video)."""
    root = tmp_path_factory.mktemp("rt")
    model = small_light_onnx(SIZE)
    clip = root / "clip"
    write_clip(SynthConfig(frames=15, height=96, width=192, seed=2), clip)
    return model, clip
