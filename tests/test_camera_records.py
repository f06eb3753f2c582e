"""The model camera on the card and the user's camera file: written once, read back, checked."""

import json
import math

import pytest

from bsn_edge.calibration import Calibration
from bsn_edge.camera import Intrinsics
from bsn_edge.card import EARLY_MOUNTING, ModelCard
from bsn_edge.mounting import Mounting
from tests.cards import card_for


def test_the_card_names_the_model_camera_and_its_horizon():
    card = card_for((128, 256)).replace(mounting=Mounting(1.4, pitch_deg=2.0))
    back = ModelCard.from_metadata(card.to_metadata())
    assert back.mounting == Mounting(1.4, pitch_deg=2.0)
    # looking down by 2 degrees puts the level horizon above the centre by fy tan(2 degrees)
    assert back.horizon_row == pytest.approx(card.camera.cy - card.camera.fy * math.tan(math.radians(2.0)))
    with pytest.raises(ValueError, match="zero yaw and roll"):
        card.replace(mounting=Mounting(1.4, 2.0, yaw_deg=1.0))


def test_a_card_written_before_the_mounting_reads_as_that_worlds_camera():
    d = card_for((128, 256)).to_dict()
    del d["mounting"]
    assert ModelCard.from_dict(d).mounting == EARLY_MOUNTING == Mounting(1.5, pitch_deg=1.5)


def test_camera_file_round_trip_and_files_from_before_mountings(tmp_path):
    k = Intrinsics(1158.8, 1154.1, 669.6, 388.1, 1280, 720)
    cal = Calibration.of(k, (-0.25, 0.04, 0.0, 0.0, -0.1), Mounting(1.25, -1.5, 0.8, 0.2), method="measured")
    cal.write(tmp_path / "c.json")
    back = Calibration.read(tmp_path / "c.json")
    assert back == cal and back.mounting_report == {"method": "measured"}
    old = json.loads((tmp_path / "c.json").read_text())
    del old["mounting"], old["mounting_report"]
    (tmp_path / "old.json").write_text(json.dumps(old))
    assert Calibration.read(tmp_path / "old.json").mounting is None
    bad = dict(old, mounting={"height_m": 9.0, "pitch_deg": 0.0, "yaw_deg": 0.0, "roll_deg": 0.0})
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(ValueError, match=r"bad\.json.*height_m"):
        Calibration.read(tmp_path / "bad.json")



def test_the_shipped_card_reads_back_to_its_stored_entries_and_a_card_without_a_record_has_none():
    """Reading and writing a sealed card gives back exactly the file's ``bsn.*`` entries (the card
    digest and the signature cover them); a card without a training record carries no entry for it,
    so cards sealed before the record existed digest as they did."""
    import onnx

    from tests.fakes import SHIPPED

    assert "training" not in card_for((64, 128)).to_dict()
    if not SHIPPED.is_file():
        pytest.skip("the shipped model is not in this checkout")
    stored = {p.key: p.value for p in onnx.load(str(SHIPPED), load_external_data=False).metadata_props}
    card = ModelCard.from_metadata(stored)
    assert card.to_metadata() == {k: v for k, v in stored.items() if k.startswith("bsn.")}
