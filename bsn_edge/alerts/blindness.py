"""Why the camera cannot see: the reason the status carries (``BSN_Status.Camera_Reason``), judged by the
runtime's camera-health check (:mod:`bsn_edge.runtime.visibility`)."""

from __future__ import annotations

from enum import IntEnum


class Blindness(IntEnum):
    """Why the camera cannot see (``BSN_Status.Camera_Reason``); CLEAR when it can. The order is the
    precedence when several hold at once."""

    CLEAR = 0
    COVERED = 1        # almost no light and no structure, or one flat grey: a cap, a cover, a dead sensor
    SATURATED = 2      # glare, a white-out, the sun in the lens: a share of the picture at full scale
    FROZEN = 3         # the same picture, to the grey level, for longer than a sensor allows
    NOISE = 4          # high-frequency energy without structure: a broken sensor or link
    BLUR = 5           # sharpness far below this camera's own: fog, dirt on the lens, heavy blur
    PARTIAL = 6        # a region covered or blinded: the sectors it covers cannot see


# reasons that blind the picture as a whole (UNAVAILABLE); PARTIAL blinds some sectors (DEGRADED)
WHOLE = frozenset({Blindness.COVERED, Blindness.SATURATED, Blindness.FROZEN, Blindness.NOISE, Blindness.BLUR})
