"""Tokens per object and speed of the PhysX geometry encodings.

``python -m scene_builder.bench.tokens`` prints, for each shape on a 64^3 grid: the template
RLE with the upstream threshold-0.5 template rule and with the exact minimum-cost choice, the
range encoding (on the same 64^3 grid, and on 32^3 as PhysX-Anything uses it), and the raw list
of occupied indices; counted in grammar units and Qwen2 pre-tokens (a lower bound of Qwen2.5
tokens, see ``tokens.count_tokens``); then encode / decode times (median of repeats).

Shapes are surface shells (PhysX voxels come from surface samples): the real cabinet 41452 parts
upsampled 2x (when ../shared is present) and procedural chair, table, cabinet, sphere, torus and a
random blob.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from generation.physx.tokens import (
    count_tokens,
    decode_omni,
    decode_ranges,
    encode_occupied_indices,
    encode_omni,
    encode_ranges,
)

G = 64


def _shell(solid: np.ndarray) -> np.ndarray:
    from scipy import ndimage

    return solid & ~ndimage.binary_erosion(solid)


def _box(occ: np.ndarray, lo, hi) -> None:
    occ[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] = True


def procedural_shapes(seed: int = 0) -> dict[str, np.ndarray]:
    """Named (64, 64, 64) bool surface shells, z up."""
    from scipy import ndimage

    g = np.indices((G, G, G)).transpose(1, 2, 3, 0) + 0.5
    out: dict[str, np.ndarray] = {}
    chair = np.zeros((G,) * 3, bool)
    for x in (8, 50):
        for y in (8, 50):
            _box(chair, (x, y, 0), (x + 5, y + 5, 30))  # legs
    _box(chair, (8, 8, 30), (56, 56, 35))  # seat
    _box(chair, (8, 50, 35), (56, 55, 64))  # back
    out["chair"] = _shell(chair)
    table = np.zeros((G,) * 3, bool)
    for x in (2, 58):
        for y in (10, 50):
            _box(table, (x, y, 0), (x + 4, y + 4, 40))
    _box(table, (0, 8, 40), (64, 56, 44))
    out["table"] = _shell(table)
    cab = np.zeros((G,) * 3, bool)
    _box(cab, (0, 16, 0), (64, 48, 56))
    cab[2:62, 18:46, 2:54] = False  # hollow with 2-voxel walls
    cab[2:62, 16:18, 2:54] = False  # open front
    _box(cab, (2, 20, 27), (62, 46, 29))  # shelf
    out["cabinet"] = cab
    out["sphere"] = _shell(np.linalg.norm(g - 32, axis=-1) < 30)
    r_xy = np.linalg.norm(g[..., :2] - 32, axis=-1)
    out["torus"] = _shell((r_xy - 20) ** 2 + (g[..., 2] - 32) ** 2 < 9**2)
    rng = np.random.default_rng(seed)
    blob = ndimage.gaussian_filter(rng.standard_normal((G,) * 3), 4) * np.exp(-np.linalg.norm(g - 32, axis=-1) ** 2 / 600)
    out["random blob"] = _shell(blob > np.quantile(blob, 0.85))
    return out


def real_shapes(protocol_dir: Path) -> dict[str, np.ndarray]:
    out = {}
    for k, name in ((0, "41452 door"), (1, "41452 frame")):
        f = protocol_dir / "PhysX-Anything" / f"41452_coord_{k}.txt"
        if f.is_file():
            occ = decode_ranges(f.read_text())
            out[name] = occ.repeat(2, 0).repeat(2, 1).repeat(2, 2)
    return out


def _median_s(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def measure(shapes: dict[str, np.ndarray], repeats: int = 5) -> list[dict]:
    rows = []
    for name, occ in shapes.items():
        texts = {
            "rle-thr0.5": encode_omni(occ, strategy="threshold"),
            "rle-opt": encode_omni(occ, strategy="optimal"),
            "range64": encode_ranges(occ, G),
            "range32": encode_ranges(occ.reshape(32, 2, 32, 2, 32, 2).any(axis=(1, 3, 5)), 32),
            "raw64": encode_occupied_indices(occ, G),
        }
        for key in ("rle-thr0.5", "rle-opt", "range64"):
            dec = decode_omni(texts[key]) if key.startswith("rle") else decode_ranges(texts[key], G)
            if not np.array_equal(dec, occ):
                raise AssertionError(f"{name}: {key} is not lossless")
        row = {"shape": name, "voxels": int(occ.sum())}
        for key, text in texts.items():
            c = count_tokens(text)
            row[key] = (c.units, c.qwen_pretokens)
        row["t_enc_thr_ms"] = 1e3 * _median_s(lambda: encode_omni(occ, strategy="threshold"), repeats)
        row["t_enc_opt_ms"] = 1e3 * _median_s(lambda: encode_omni(occ, strategy="optimal"), repeats)
        row["t_dec_rle_ms"] = 1e3 * _median_s(lambda: decode_omni(texts["rle-opt"]), repeats)
        row["t_enc_range_ms"] = 1e3 * _median_s(lambda: encode_ranges(occ, G), repeats)
        row["t_dec_range_ms"] = 1e3 * _median_s(lambda: decode_ranges(texts["range64"], G), repeats)
        rows.append(row)
    return rows


def format_table(rows: list[dict]) -> str:
    keys = ("rle-thr0.5", "rle-opt", "range64", "range32", "raw64")
    head = "| shape | voxels | " + " | ".join(f"{k} units / qwen" for k in keys)
    head += " | enc thr ms | enc opt ms | dec rle ms | enc range ms | dec range ms |"
    lines = [head, "|" + "---|" * (2 + len(keys) + 5)]
    for r in rows:
        cells = [r["shape"], str(r["voxels"])] + [f"{r[k][0]} / {r[k][1]}" for k in keys]
        cells += [f"{r[k]:.1f}" for k in ("t_enc_thr_ms", "t_enc_opt_ms", "t_dec_rle_ms", "t_enc_range_ms", "t_dec_range_ms")]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol-dir", type=Path, default=Path(__file__).resolve().parents[3] / "shared" / "data" / "physx_protocol")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    shapes = real_shapes(args.protocol_dir) | procedural_shapes()
    print(format_table(measure(shapes, args.repeats)))


if __name__ == "__main__":
    main()
