"""Shared test set-up: headless rendering, paths to the shared real data.

Without ``../shared`` the tests that need it skip, with the reason, on a developer's machine. Under
``CI=true`` a missing ``../shared/data`` or ``../shared/models`` stops the run at once with a
clear message, and any skip for want of shared data is reported as a failure: CI must never pass
while testing nothing real.
"""

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


def in_ci() -> bool:
    """True when the environment says this is a CI run (``CI=true``, as GitHub Actions and
    GitLab set it)."""
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


def _missing_shared() -> list[Path]:
    return [p for p in (SHARED / "data", SHARED / "models") if not p.is_dir()]


def pytest_sessionstart(session) -> None:
    if in_ci() and (missing := _missing_shared()):
        pytest.exit(
            f"CI=true but the shared data is missing: {', '.join(map(str, missing))}; "
            "check out or mount ../shared beside the repository (the real-data tests would otherwise skip)",
            returncode=1,
        )


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under CI, a test skipped for want of shared data fails instead (an expected failure, which
    pytest reports as skipped with ``wasxfail``, is not a skip: its message may name a path under
    ../shared)."""
    outcome = yield
    report = outcome.get_result()
    if in_ci() and report.skipped and not hasattr(report, "wasxfail") and "shared" in str(report.longrepr).lower():
        report.outcome = "failed"
        report.longrepr = f"CI=true: skipped for want of shared data, which CI must provide: {report.longrepr}"


def require(path: Path) -> Path:
    """Skip the calling test (with the reason) when a shared data folder is absent; under
    ``CI=true`` fail it instead."""
    if not path.exists():
        message = f"shared data not present: {path} (the tests use ../shared beside the checkout)"
        if in_ci():
            pytest.fail(f"CI=true: {message}", pytrace=False)
        pytest.skip(message)
    return path


def real_samples(with_intrinsics: bool = True) -> list[Path]:
    """Sample folders under ../shared/data/real that have aligned depth (and camera.json); empty
    without the shared data (the tests using them skip), an error under ``CI=true``."""
    if not REAL_DATA.exists():
        if in_ci():
            raise RuntimeError(f"CI=true but {REAL_DATA} is missing; check out or mount ../shared beside the repository")
        return []
    out = []
    for d in sorted(REAL_DATA.iterdir()):
        if not (d / "depth.png").exists():
            continue
        if with_intrinsics and not (d / "camera.json").exists():
            continue
        out.append(d)
    return out


def build_sample(src: Path, out: Path, viz: str = "off", **export):
    """Build the RGB-D sample folder ``src`` (rgb.jpg or rgb.png, depth.png in millimetres,
    camera.json) into ``out`` with the default configuration (``export``: ExportConfig fields to
    change, e.g. ``scene_urdf=True``); returns the pipeline's BuildResult."""
    import json

    from scene_builder.config import BuildConfig, ExportConfig, InputSpec
    from scene_builder.pipeline import build

    cam = json.loads((src / "camera.json").read_text())
    rgb = src / ("rgb.jpg" if (src / "rgb.jpg").exists() else "rgb.png")
    inputs = InputSpec(rgb, src / "depth.png", 0.001, (cam["fx"], cam["fy"], cam["cx"], cam["cy"]))
    return build(inputs, out, BuildConfig(export=ExportConfig(viz=viz, **export)))


def real_sample_params(with_intrinsics: bool = True) -> list:
    """``real_samples`` as pytest parameters named after the sample, each in the xdist group of
    its name: under ``pytest -n 2 --dist loadgroup`` (``make test``) every test of one sample
    runs on the same worker and shares its build (:func:`built_real_sample`)."""
    return [pytest.param(s, id=s.name, marks=pytest.mark.xdist_group(s.name)) for s in real_samples(with_intrinsics)]


_REAL_BUILDS: dict[str, object] = {}


@pytest.fixture(scope="session")
def built_real_sample(tmp_path_factory):
    """``get(sample)``: the BuildResult of the real sample folder, built once per test session
    (worker) with :func:`build_sample` and shared by the test modules that read it."""

    def get(sample: Path):
        if sample.name not in _REAL_BUILDS:
            _REAL_BUILDS[sample.name] = build_sample(sample, tmp_path_factory.mktemp(sample.name) / "out")
        return _REAL_BUILDS[sample.name]

    return get


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


SDF_CHECK_SOURCE = REPO / "scripts" / "sdf_check.cc"


@pytest.fixture(scope="session")
def sdf_checker(tmp_path_factory) -> list[str]:
    """The libsdformat checker (``scripts/sdf_check.cc``) compiled once per session with g++ and
    pkg-config: the command that loads an SDF file with the SDFormat library. Skips (fails under
    ``CI=true``, where ``scripts/bootstrap.sh`` installs libsdformat-dev) when it cannot be built."""
    import shutil
    import subprocess

    reason = None
    if shutil.which("g++") is None or shutil.which("pkg-config") is None:
        reason = "g++ and pkg-config are needed to build the SDFormat checker"
    else:
        flags = subprocess.run(["pkg-config", "--cflags", "--libs", "sdformat12"], capture_output=True, text=True)
        if flags.returncode != 0:
            reason = "libsdformat is not installed (apt-get install libsdformat-dev)"
    if reason is not None:
        if in_ci():
            pytest.fail(f"CI=true: {reason}", pytrace=False)
        pytest.skip(reason)
    exe = tmp_path_factory.mktemp("sdf_check") / "sdf_check"
    build = subprocess.run(["g++", "-O1", "-o", str(exe), str(SDF_CHECK_SOURCE), *flags.stdout.split()], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    return [str(exe)]
