"""Map files: ROS map_server (PGM + YAML, trinary), ``.npz`` (log-odds, lossless) and a PNG to look at.

map_server convention: the PGM's first row is the top of the map (largest y); ``origin`` is the world
pose of the lower-left pixel; with negate 0, p_occ = (255 - pixel) / 255; we write 0 = occupied,
254 = free, 205 = unknown.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.io.errors import LogDefectWarning
from irmcl_warp.io.plausibility import check_map
from irmcl_warp.mapping.grid import OccupancyGrid

OCCUPIED_THRESH, FREE_THRESH = 0.65, 0.196  # map_server's defaults


def to_trinary(grid: OccupancyGrid) -> np.ndarray:
    p = grid.probability
    img = np.full(p.shape, 205, dtype=np.uint8)
    img[grid.known & (p >= OCCUPIED_THRESH)] = 0
    img[grid.known & (p <= FREE_THRESH)] = 254
    return img[::-1]  # first row = top


def occupancy_data(grid: OccupancyGrid) -> np.ndarray:
    """The grid as ROS's nav_msgs/OccupancyGrid data [H, W] int8, read as the trinary map files are (to_trinary):
    100 occupied, 0 free, -1 unknown; row 0 at the origin."""
    image = to_trinary(grid)[::-1]
    return np.where(image == 0, 100, np.where(image == 254, 0, -1)).astype(np.int8)


def save_map(grid: OccupancyGrid, stem) -> dict[str, Path]:
    """Write ``stem.pgm``, ``stem.yaml``, ``stem.npz`` and ``stem.png``; returns their paths."""
    stem = Path(stem)
    img = to_trinary(grid)
    H, W = img.shape
    atomic_write_bytes(stem.with_suffix(".pgm"), f"P5\n{W} {H}\n255\n".encode() + img.tobytes())
    yaml = (
        f"image: {stem.name}.pgm\nresolution: {grid.resolution_m}\n"
        f"origin: [{grid.origin_xy[0]}, {grid.origin_xy[1]}, 0.0]\nnegate: 0\n"
        f"occupied_thresh: {OCCUPIED_THRESH}\nfree_thresh: {FREE_THRESH}\nmode: trinary\n"
    )
    atomic_write_bytes(stem.with_suffix(".yaml"), yaml.encode())
    import io

    buf = io.BytesIO()
    np.savez_compressed(buf, logodds=grid.logodds, origin_xy=np.array(grid.origin_xy), resolution_m=grid.resolution_m)
    atomic_write_bytes(stem.with_suffix(".npz"), buf.getvalue())
    buf = io.BytesIO()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.imsave(buf, img, cmap="gray", vmin=0, vmax=255, format="png")
    atomic_write_bytes(stem.with_suffix(".png"), buf.getvalue())
    return {k: stem.with_suffix("." + k) for k in ("pgm", "yaml", "npz", "png")}


def _read_pgm(path: Path) -> np.ndarray:
    data = path.read_bytes()
    tokens, pos = [], 0
    while len(tokens) < 4:
        while pos < len(data) and chr(data[pos]).isspace():
            pos += 1
        if pos < len(data) and data[pos : pos + 1] == b"#":
            pos = data.find(b"\n", pos) + 1
            if pos == 0:
                raise ValueError(f"{path}: truncated PGM header (a comment runs to the end of the file)")
            continue
        start = pos
        while pos < len(data) and not chr(data[pos]).isspace():
            pos += 1
        if start == pos:
            raise ValueError(f"{path}: truncated PGM header")
        tokens.append(data[start:pos].decode("ascii", "replace"))
    if tokens[0] != "P5":
        raise ValueError(f"{path}: expected a binary PGM (P5), found {tokens[0]!r}")
    if not all(t.isdigit() and 0 < int(t) < 1 << 16 for t in tokens[1:4]):
        raise ValueError(
            f"{path}: PGM width, height and maxval must be whole numbers from 1 to 65535, found "
            f"{[t[:20] for t in tokens[1:4]]}"
        )
    W, H, maxval = int(tokens[1]), int(tokens[2]), int(tokens[3])
    pixels = data[pos + 1 :]
    if maxval > 255 or len(pixels) < W * H:
        raise ValueError(f"{path}: expected {W}x{H} 8-bit pixels, found {len(pixels)} bytes")
    return np.frombuffer(pixels[: W * H], dtype=np.uint8).reshape(H, W)


def _read_image(path: Path) -> np.ndarray:
    """8-bit grey pixels of a map image: binary PGM, or PNG (colour averaged to grey, as map_server)."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the map image named by the map YAML is missing")
    if path.suffix.lower() in (".pgm", ".pnm"):
        return _read_pgm(path)
    import matplotlib.image

    try:
        img = matplotlib.image.imread(path)
    except (OSError, ValueError, SyntaxError) as e:
        raise ValueError(f"{path}: not a readable map image ({e})") from e
    img = np.asarray(img, np.float64)
    if img.ndim == 3:
        img = img[..., :3].mean(-1)
    return np.round(img * 255.0 if img.max() <= 1.0 else img).astype(np.uint8)


DECIMAL = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def _number(path, key, text):
    """A YAML scalar as a float, written as a decimal number: YAML 1.1 would read ``0x05`` as 5 and ``1_0`` as
    10, which a damaged file can turn a value into."""
    if not isinstance(text, str) or not DECIMAL.fullmatch(text.strip()):
        raise ValueError(f"{path}: {key} must be a decimal number, found {text!r}")
    return float(text)


def _read_map_yaml(path: Path) -> dict:
    """map_server's keys, numbers parsed strictly; unknown keys are left alone, as map_server does."""
    import yaml

    try:
        text = path.read_bytes().decode("utf-8")
        raw = yaml.load(text, Loader=yaml.BaseLoader)  # every scalar a string: the numbers are checked here
    except Exception as e:  # decoding and the YAML parser raise many types
        raise ValueError(f"{path}: not a map_server YAML ({type(e).__name__}: {str(e)[:300]})") from e
    if not isinstance(raw, dict):
        raise ValueError(f"{path}: not a map_server YAML (expected keys image, resolution, origin)")
    for key in ("image", "resolution", "origin"):
        if key not in raw:
            raise ValueError(f"{path}: map YAML lacks {key!r}")
    if text and not text.endswith("\n"):
        warnings.warn(
            f"{path}: ends without a newline: if it was cut off, its last value may be cut too",
            LogDefectWarning,
            stacklevel=3,
        )
    meta = dict(raw)
    if not isinstance(raw["origin"], list):
        raise ValueError(f"{path}: origin must be [x, y, yaw], found {raw['origin']!r}")
    meta["origin"] = [_number(path, "origin", v) for v in raw["origin"]]
    meta["resolution"] = _number(path, "resolution", raw["resolution"])
    for key in ("occupied_thresh", "free_thresh"):
        if key in raw:
            meta[key] = _number(path, key, raw[key])
    if "negate" in raw:
        meta["negate"] = {"0": 0, "1": 1, "false": 0, "true": 1}.get(str(raw["negate"]).strip().lower(), raw["negate"])
    return meta


def load_map(path) -> OccupancyGrid:
    """Load ``.npz`` (exact) or a map_server ``.yaml`` (+ its PGM or PNG; trinary: occupied above
    occupied_thresh, free below free_thresh, unknown between; ``negate`` flips the pixel scale). A rotated
    origin (yaw) is refused: the grids here are axis-aligned."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such map file (a map_server .yaml or a .npz)")
    if path.suffix == ".npz":
        with np.load(path) as z:
            grid = OccupancyGrid(z["logodds"], tuple(z["origin_xy"].tolist()), float(z["resolution_m"]))
        check_map(path, grid.probability, grid.known)  # mostly walls: an inverted map, say so
        return grid
    meta = _read_map_yaml(path)
    origin, res = meta["origin"], meta["resolution"]
    if not (
        isinstance(origin, list)
        and len(origin) in (2, 3)
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v) < 1e7 for v in origin)
    ):
        raise ValueError(f"{path}: origin must be [x, y, yaw], found {origin!r}")
    if len(origin) == 3 and abs(origin[2]) > 1e-9:
        raise ValueError(f"{path}: origin yaw {origin[2]} is not supported (rotate the image into the map frame)")
    if isinstance(res, bool) or not (isinstance(res, (int, float)) and 0 < res < 1e3):
        raise ValueError(f"{path}: resolution must be a positive number of metres per pixel, found {res!r}")
    occ_t, free_t = meta.get("occupied_thresh", OCCUPIED_THRESH), meta.get("free_thresh", FREE_THRESH)
    negate, mode = meta.get("negate", 0), meta.get("mode", "trinary")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (occ_t, free_t)):
        raise ValueError(f"{path}: occupied_thresh and free_thresh must be numbers, found {occ_t!r}, {free_t!r}")
    if negate not in (0, 1) or isinstance(negate, float):
        raise ValueError(f"{path}: negate must be 0 or 1, found {negate!r}")
    if mode != "trinary":
        raise ValueError(f"{path}: mode {mode!r}: only map_server's trinary maps are read here")
    if not isinstance(meta["image"], str):
        raise ValueError(f"{path}: image must be a file name, found {meta['image']!r}")
    if not 0 <= free_t < occ_t <= 1:
        raise ValueError(f"{path}: expected 0 <= free_thresh < occupied_thresh <= 1, found {free_t}, {occ_t}")
    try:
        img = _read_image(path.parent / meta["image"])[::-1].astype(np.float64)
    except FileNotFoundError as e:
        raise FileNotFoundError(f"{path}: its image {meta['image']!r}: {e}") from e
    except ValueError as e:
        raise ValueError(f"{path}: its image {meta['image']!r}: {e}") from e
    p = (255.0 - img) / 255.0 if not negate else img / 255.0
    logodds = np.zeros(p.shape, dtype=np.float32)
    logodds[p > occ_t] = 4.0
    logodds[p < free_t] = -4.0
    grid = OccupancyGrid(logodds, (float(origin[0]), float(origin[1])), float(res))
    check_map(path, grid.probability, grid.known)
    return grid
