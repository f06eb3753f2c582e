"""The self-test's tolerances, at their edges: a model answering just inside passes, just outside is refused."""

import numpy as np
import pytest

from bsn_edge.card import FP32
from bsn_edge.modelfile import selftest
from bsn_edge.modelfile.selftest import TOLERANCE, SelfTestError

SIZE = (64, 128)


def model(shift_p: float = 0.0, scale_d: float = 1.0):
    """A deterministic stand-in for a network: probability and depth from the frame's pixels."""
    def infer(frame):
        g = frame.mean(axis=2).astype(np.float32) / 255.0
        return np.clip(0.2 + 0.5 * g + shift_p, 0, 1), (5.0 + 20.0 * g) * scale_d
    return infer


# the schemes cards say, as the export writes them: fp32, fp32 as sealed while its name was shadowed, int8's
SCHEMES = [(FP32, "fp32"), ("fp32", "fp32"),
           ("static QDQ, activations uint8, weights int8 (7-bit range) per-channel, minmax calibration", "int8"),
           ("static QDQ, activations uint8, weights int8 per-channel, minmax calibration, integer input", "int8")]


@pytest.mark.parametrize("quantization,kind", SCHEMES)
def test_answers_within_the_stated_tolerance_pass_and_beyond_it_are_refused(quantization, kind):
    expected = selftest.record(model(), SIZE, quantization)
    atol, rtol = TOLERANCE[kind]
    assert (expected.prob_atol, expected.depth_rtol) == (atol, rtol)
    assert (atol, rtol) == ((2e-3, 2e-3) if kind == "fp32" else (0.05, 0.05)), "the README's figures"
    selftest.check(model(shift_p=0.9 * atol), SIZE, expected)
    selftest.check(model(scale_d=1 + 0.9 * rtol), SIZE, expected)
    with pytest.raises(SelfTestError, match="probabilities differ"):
        selftest.check(model(shift_p=1.2 * atol), SIZE, expected)
    with pytest.raises(SelfTestError, match="depth by up to"):
        selftest.check(model(scale_d=1 + 1.2 * rtol), SIZE, expected)
