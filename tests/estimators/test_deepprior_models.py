"""DeepPrior models: output shapes, the PCA-initialized prior, checkpoints with weights_only."""

import json

import numpy as np
import pytest
import torch

from handsim.estimators.deepprior import checkpoint as C
from handsim.estimators.deepprior.models import (
    DeepPriorNet,
    DeepPriorPP,
    Localizer,
    PriorLayer,
    build_model,
    inference_forward,
)
from handsim.estimators.deepprior.preprocess import fit_pca


@pytest.mark.parametrize("variant", ["shallow", "deep", "multiscale"])
@pytest.mark.parametrize("prior_dim", [None, 8, 30])
def test_deepprior_output_shapes(variant, prior_dim):
    """Every DeepPrior variant maps (B, 1, S, S) to (B, 63); the prior layer iff prior_dim."""
    net = DeepPriorNet(variant, prior_dim, size=64, fc=32).eval()
    assert net(torch.zeros(3, 1, 64, 64)).shape == (3, 63)
    has_prior = any(isinstance(m, PriorLayer) for m in net.modules())
    assert has_prior == bool(prior_dim)


@pytest.mark.parametrize("width", [1.0, 0.25])
def test_deepprior_pp_output_shape_and_stages(width):
    """DeepPrior++: 63 outputs, four stages 64/128/256/256 (x width), no GAP, dropout 0.3."""
    net = DeepPriorPP(30, size=128, fc=64, width=width).eval()
    assert net(torch.zeros(2, 1, 128, 128)).shape == (2, 63)
    convs = [m for m in net.features.modules() if isinstance(m, torch.nn.Conv2d)]
    assert convs[0].out_channels == round(64 * width)
    assert [m.out_channels for m in convs if m.kernel_size == (1, 1)] == [
        round(w * width) for w in (64, 128, 256, 256)
    ]
    assert not any(isinstance(m, torch.nn.AdaptiveAvgPool2d) for m in net.modules())
    drops = [m.p for m in net.head.modules() if isinstance(m, torch.nn.Dropout)]
    assert drops == [0.3, 0.3]


def test_localizer_output_shape():
    """The localizer predicts a (B, 3) offset."""
    assert Localizer(size=64, fc=32).eval()(torch.zeros(4, 1, 64, 64)).shape == (4, 3)


def test_build_model_rejects_unknown_arch():
    """An unknown arch names the valid ones."""
    with pytest.raises(ValueError, match="arch must be one of"):
        build_model({"arch": "vgg"})


def test_pca_init_equals_the_pca_projection_before_training():
    """With the encoder set to the PCA projection, the prior layer is the PCA reconstruction."""
    rng = np.random.default_rng(0)
    poses = rng.normal(size=(300, 63)) @ rng.normal(size=(63, 63)) * 0.1
    pca = fit_pca(poses, 30)
    layer = PriorLayer(63, 30)
    layer.init_from_pca(pca["mean"], pca["components"])
    with torch.no_grad():
        layer.encode.weight.copy_(torch.as_tensor(pca["components"], dtype=torch.float32))
        layer.encode.bias.copy_(
            torch.as_tensor(-pca["components"] @ pca["mean"], dtype=torch.float32)
        )
        out = layer(torch.as_tensor(poses, dtype=torch.float32)).double().numpy()
    coeffs = (poses - pca["mean"]) @ pca["components"].T
    expected = coeffs @ pca["components"] + pca["mean"]
    np.testing.assert_allclose(out, expected, atol=1e-4)
    # The decoder alone maps coefficients to poses: weight = components^T, bias = mean.
    np.testing.assert_allclose(layer.decode.weight.detach().numpy(), pca["components"].T, atol=1e-7)
    np.testing.assert_allclose(layer.decode.bias.detach().numpy(), pca["mean"], atol=1e-7)


def test_checkpoint_round_trip_with_weights_only(tmp_path):
    """save_checkpoint + load_model (torch.load weights_only=True) gives the same outputs."""
    config = {
        "model": {"arch": "resnet", "size": 64, "fc": 32, "width": 0.25, "prior_dim": 8},
        "cube_m": 0.25,
        "kind": "deepprior++",
    }
    torch.manual_seed(0)
    net = build_model(config["model"]).eval()
    C.save_checkpoint(tmp_path / "m.pt", {"model": net.state_dict()}, config)
    assert json.loads((tmp_path / "m.json").read_text()) == config
    loaded, cfg = C.load_model(tmp_path / "m.pt")
    x = torch.randn(2, 1, 64, 64)
    with torch.no_grad():
        torch.testing.assert_close(loaded(x), net(x))
    assert cfg == config
    # a training folder resolves to its best.pt
    C.save_checkpoint(tmp_path / "best.pt", {"model": net.state_dict()}, config)
    assert C.resolve_checkpoint(tmp_path) == tmp_path / "best.pt"


def test_checkpoint_errors_name_what_is_valid(tmp_path):
    """Missing and unreadable checkpoints raise InvalidCheckpoint with the reason."""
    with pytest.raises(C.InvalidCheckpoint, match="give a shipped name"):
        C.resolve_checkpoint(tmp_path / "nope.pt")
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(C.InvalidCheckpoint, match="cannot read checkpoint"):
        C.load_checkpoint(tmp_path / "bad.pt")


def test_precise_bn_gives_plain_averages_of_batch_statistics():
    """precise_bn: each batch norm's statistics = the mean of its per-batch ones; rest untouched."""
    from handsim.estimators.deepprior.train import precise_bn

    torch.manual_seed(0)
    config = {
        "arch": "resnet",
        "size": 32,
        "fc": 16,
        "dropout": 0.3,
        "prior_dim": 4,
        "width": 0.125,
    }
    model = build_model(config)
    model.train()
    for _ in range(3):  # momentum statistics, as training leaves them
        model(torch.randn(8, 1, 32, 32) * 3.0 + 1.0)
    dataset = [(torch.randn(1, 32, 32) * 0.5 - 0.2, torch.zeros(63)) for _ in range(40)]
    first = next(m for m in model.modules() if isinstance(m, torch.nn.BatchNorm2d))
    seen = []
    hook = first.register_forward_hook(lambda m, inputs, out: seen.append(inputs[0].detach()))
    weights = {k: v.clone() for k, v in model.state_dict().items() if "running" not in k}
    rng_state = torch.get_rng_state()
    precise_bn(model, dataset, batch_size=8, batches=3, seed=1)
    hook.remove()
    assert len(seen) == 3 and model.training  # 3 batches; the mode is restored
    means = torch.stack([x.mean(dim=(0, 2, 3)) for x in seen]).mean(dim=0)
    variances = torch.stack([x.var(dim=(0, 2, 3), unbiased=True) for x in seen]).mean(dim=0)
    torch.testing.assert_close(first.running_mean, means, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(first.running_var, variances, rtol=1e-5, atol=1e-6)
    assert first.momentum == 0.1
    for key, value in weights.items():
        if "num_batches" not in key:
            torch.testing.assert_close(model.state_dict()[key], value, msg=key)
    assert torch.equal(torch.get_rng_state(), rng_state)  # dropout drew nothing
    precise_bn(model, dataset[:9], batch_size=8, batches=2)  # a last batch of one is skipped
    assert torch.isfinite(first.running_var).all()


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        ("nan", r"has non-finite weights \(NaN or inf\) in '.*': the run that wrote it diverged"),
        ("not_tensors", r"'model' must map parameter names to tensors"),
        ("wrong_keys", r"does not fit its network: RuntimeError"),
        ("config_list", r"must be a JSON object with a 'model' mapping"),
    ],
)
def test_a_broken_checkpoint_is_refused_naming_it(tmp_path, damage, message):
    """NaN weights, non-tensor values, wrong keys, a config that is no mapping: named errors."""
    import json
    import shutil

    import torch

    from handsim.estimators.deepprior.checkpoint import (
        WEIGHTS_DIR,
        InvalidCheckpoint,
        load_model,
    )

    path = tmp_path / "broken.pt"
    shutil.copy(WEIGHTS_DIR / "localizer.json", path.with_suffix(".json"))
    state = torch.load(WEIGHTS_DIR / "localizer.pt", map_location="cpu", weights_only=True)
    first = next(k for k, v in state["model"].items() if v.is_floating_point())
    if damage == "nan":
        state["model"][first] = torch.full_like(state["model"][first], float("nan"))
    elif damage == "not_tensors":
        state["model"] = {k: 1.0 for k in state["model"]}
    elif damage == "wrong_keys":
        state["model"] = {f"other.{k}": v for k, v in state["model"].items()}
    else:
        path.with_suffix(".json").write_text(json.dumps([1, 2]))
    torch.save(state, path)
    with pytest.raises(InvalidCheckpoint, match=message):
        load_model(path)


@pytest.mark.parametrize(
    "config",
    [
        {"arch": "shallow", "size": 64, "fc": 32, "prior_dim": 8},
        {"arch": "deep", "size": 64, "fc": 32, "prior_dim": 8},
        {"arch": "deep", "size": 64, "fc": 32, "prior_dim": 0},
        {"arch": "multiscale", "size": 64, "fc": 32, "prior_dim": 8},
        {"arch": "resnet", "size": 64, "fc": 32, "prior_dim": 8, "width": 0.125},
        {"arch": "localizer", "size": 32, "fc": 16},
        {"arch": "detector", "size": 32, "channels": 8},
    ],
)
def test_inference_forward_equals_the_module_forward(config):
    """The unrolled, batch-norm-folded inference pass gives the eval-mode module's output."""
    torch.manual_seed(0)
    net = build_model(config)
    for m in net.modules():  # non-trivial batch-norm statistics
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    net = net.eval().to(memory_format=torch.channels_last)
    channels = 2 if config["arch"] == "detector" else 1  # depth and its mask
    x = torch.randn(3, channels, config["size"], config["size"]).contiguous(
        memory_format=torch.channels_last
    )
    with torch.inference_mode():
        torch.testing.assert_close(inference_forward(net)(x), net(x), rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="needs a model in eval mode"):
        inference_forward(net.train())


@pytest.mark.parametrize("name", sorted(C.SHIPPED))
def test_every_shipped_network_loads_in_float32_and_predicts(name):
    """The shipped weights (float16 or float32 on disk) load as float32 and give finite output."""
    model, config = C.load_model(name)
    assert config["canonical_side"] is True
    assert all(p.dtype == torch.float32 for p in model.parameters())
    if name == "detector":  # the whole image in, a grid out
        from handsim.estimators.deepprior.detector import GRID_H, GRID_W, INPUT_H, INPUT_W

        x, shape = torch.zeros(1, 2, INPUT_H, INPUT_W), (1, 4, GRID_H, GRID_W)
    else:
        size = int(config["model"]["size"])
        x, shape = torch.zeros(1, 1, size, size), (1, 3 if name == "localizer" else 63)
    with torch.inference_mode():
        out = model(x)
    assert out.shape == shape
    assert torch.isfinite(out).all()
