import os

import numpy as np
import pytest

from bsn_edge.camera import Intrinsics
from bsn_edge.synth import RoadLayout


@pytest.fixture
def straight_road() -> RoadLayout:
    """One road along y at x = 0: one lane each way (3.2 m), 2.2 m parking, 2.5 m sidewalks."""
    return RoadLayout(np.array([0.0]), np.array([1]), np.array([]), np.array([], int))


@pytest.fixture
def small_camera() -> Intrinsics:
    return Intrinsics.from_fov(256, 128, 80.0)


@pytest.fixture(autouse=True, scope="session")
def _sample_cache_in_tmp(tmp_path_factory) -> None:
    """Training's sample caches go to a temporary folder, never the user's cache folder."""
    os.environ["BSN_EDGE_CACHE"] = str(tmp_path_factory.mktemp("sample-cache"))


@pytest.fixture(autouse=True, scope="session")
def tests_key(tmp_path_factory):
    """The tests' own signing key, trusted through a trust folder of its own (``BSN_EDGE_TRUST``), as a
    user's is: models the tests make for ``bsn-run`` are signed with it
    (``bsn_edge.export.signing.sign(model, tests_key)``); the user's own trust folder is never read."""
    from bsn_edge.export.signing import new_key
    folder = tmp_path_factory.mktemp("trust")
    priv, _, _ = new_key(tmp_path_factory.mktemp("keys") / "tests.pem")
    (folder / "tests.pub").write_bytes(priv.with_name("tests.pem.pub").read_bytes())
    os.environ["BSN_EDGE_TRUST"] = str(folder)
    return priv


@pytest.fixture(scope="session")
def small_light_onnx(tmp_path_factory, tests_key):
    """An untrained ``small-light`` (seed 0) exported fp32 and signed with the tests' key, once per size
    for the whole run: ``small_light_onnx((h, w)) -> path``. Shared: read it, never change it."""
    import torch

    from bsn_edge.export import to_onnx
    from bsn_edge.export.signing import sign
    from bsn_edge.networks import create_model
    from tests.cards import card_for
    made = {}

    def exported(size: tuple[int, int]):
        if size not in made:
            torch.manual_seed(0)
            made[size] = tmp_path_factory.mktemp("small_light") / "m.onnx"
            to_onnx(create_model("small-light").eval(), made[size], card_for(size))
            sign(made[size], tests_key)
        return made[size]
    return exported
