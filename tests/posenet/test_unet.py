import pytest
import torch

from posenet.net.inputs import InputConfig
from posenet.net.unet import UNet, UNetConfig


@pytest.mark.parametrize("modality,channels", [("rgbd", 5), ("depth", 2), ("rgb", 4)])
def test_paper_channel_counts(modality, channels):
    assert InputConfig(modality=modality, extra_depth=False).in_channels == channels


@pytest.mark.parametrize("depth", [2, 3])
def test_shapes_and_finite(depth):
    torch.manual_seed(0)
    net = UNet(UNetConfig(in_channels=5, base=4, depth=depth))
    y = net(torch.randn(2, 5, 32, 48))
    assert y.shape == (2, 10, 32, 48)
    assert torch.isfinite(y).all()


def test_batched_equals_single_in_eval():
    torch.manual_seed(0)
    net = UNet(UNetConfig(in_channels=3, base=4, depth=2)).eval()
    x = torch.randn(3, 3, 16, 16)
    with torch.no_grad():
        batched = net(x)
        single = torch.cat([net(x[i : i + 1]) for i in range(3)])
    torch.testing.assert_close(batched, single, atol=1e-5, rtol=1e-5)


def test_head_is_linear():
    net = UNet(UNetConfig(in_channels=2, base=4, depth=2))
    assert isinstance(net.head, torch.nn.Conv2d) and net.head.kernel_size == (1, 1)
    assert list(net.children())[-1] is net.head  # no activation after the last layer


def test_bad_inputs_raise():
    net = UNet(UNetConfig(in_channels=5, base=4, depth=2))
    with pytest.raises(ValueError, match="multiples of 4"):
        net(torch.zeros(1, 5, 10, 16))
    with pytest.raises(ValueError, match=r"\(N, 5, H, W\)"):
        net(torch.zeros(1, 4, 16, 16))


def test_flops_scale_with_area_and_keep_bn_state():
    net = UNet(UNetConfig(in_channels=5, base=4, depth=2)).train()
    before = net.stem[1].running_mean.clone()
    f1, f2 = net.flops(32, 32), net.flops(64, 64)
    assert f1 > 0 and f2 == 4 * f1
    torch.testing.assert_close(net.stem[1].running_mean, before)
    assert net.training


def test_widening_computes_the_same_and_then_learns():
    from posenet.net.unet import widen_state_dict

    torch.manual_seed(0)
    small_cfg, wide_cfg = (
        UNetConfig(in_channels=5, base=4, depth=2),
        UNetConfig(in_channels=5, base=6, depth=2),
    )
    small = UNet(small_cfg)
    small(torch.randn(4, 5, 16, 16))  # BatchNorm statistics of its own, not the initial ones
    wide = UNet(wide_cfg)
    wide.load_state_dict(widen_state_dict(small.state_dict(), small_cfg, wide))
    x = torch.randn(3, 5, 16, 16)
    for training in (False, True):
        small.train(training), wide.train(training)
        torch.testing.assert_close(wide(x), small(x), rtol=0, atol=1e-6)
    # The new channels start disconnected from the logits, but what leaves them gets a gradient at once.
    wide(x).square().mean().backward()
    assert wide.head.weight.grad[:, 4:].abs().sum() > 0
    assert wide.downs[0][0].weight.grad[:8, 4:].abs().sum() > 0  # old channels from new inputs
    with pytest.raises(ValueError, match="narrower"):
        widen_state_dict(wide.state_dict(), wide_cfg, UNet(small_cfg))
    with pytest.raises(ValueError, match="depth"):
        widen_state_dict(small.state_dict(), small_cfg, UNet(UNetConfig(in_channels=5, base=6, depth=3)))
