"""Shared test set-up: headless rendering, paths to the shared real data (tests skip without it)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# MuJoCo picks its GL backend at import: render offscreen on the CPU (Mesa llvmpipe via EGL).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
# Tests never reach the real model hub: the download tests serve a local hub (HF_ENDPOINT) and
# switch this off for themselves.
os.environ.setdefault("HF_HUB_OFFLINE", "1")

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
REAL_DATA = SHARED / "data" / "real"
PHOTOS = SHARED / "data" / "photos"
PHYSX_PROTOCOL = SHARED / "data" / "physx_protocol"
MODELS = SHARED / "models"


def require(path: Path) -> Path:
    """Skip the calling test (with the reason) when a shared data folder is absent."""
    if not path.exists():
        pytest.skip(f"shared data not present: {path} (the tests use ../shared beside the checkout)")
    return path


def real_samples(with_intrinsics: bool = True) -> list[Path]:
    """Sample folders under ../shared/data/real that have aligned depth (and camera.json)."""
    if not REAL_DATA.exists():
        return []
    out = []
    for d in sorted(REAL_DATA.iterdir()):
        if not (d / "depth.png").exists():
            continue
        if with_intrinsics and not (d / "camera.json").exists():
            continue
        out.append(d)
    return out


@pytest.fixture(scope="session")
def newton():
    """NVIDIA Newton, the independent UsdPhysics consumer (its kernels are cached under .cache/warp)."""
    os.environ.setdefault("WARP_CACHE_PATH", str(REPO / ".cache" / "warp"))
    newton = pytest.importorskip("newton")
    import warp as wp

    wp.config.quiet = True
    return newton


def load_newton_model(newton, usd_path: Path):
    """A finalised Newton model of the USD file, on the CPU."""
    builder = newton.ModelBuilder()
    builder.add_usd(str(usd_path))
    return builder.finalize(device="cpu")
