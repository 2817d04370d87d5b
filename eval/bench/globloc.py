"""``python -m eval.bench globloc [--exp globloc_corridor] [--device cpu|cuda:0] [--frames 30] [--keyframes 1000]``

Per camera frame of the lidar + camera pipeline: rendering (frames/s of a batch), the Gist of one query,
retrieval over the keyframe database, ORB + PnP per candidate keyframe, Scan2Map per candidate, and the
whole relocalization decision (Gist -> retrieval -> clusters -> PnP -> Scan2Map). The database is the
experiment's mapping run, cut or repeated to ``--keyframes`` entries. Prints a table and writes
outputs/bench/globloc-<exp>-<device>.json.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from eval.bench.timing import record_path
from irmcl_warp.services.outputs import write_json
from irmcl_warp.config import compose_config
from irmcl_warp.geometry import compose as compose_se2
from irmcl_warp.globloc.database import build_database, describe, keyframe_indices
from irmcl_warp.globloc.gist import Gist
from irmcl_warp.globloc.run import Hypotheses, grid_of, laser_angles, make_stream, world_of
from irmcl_warp.globloc.scan2map import Scan2Map
from irmcl_warp.sim.camera import Camera, Session, appearance
from irmcl_warp.sim.trajectory import follow, waypoints
from irmcl_warp.kernels import pick_device


def add_parser(sub) -> None:
    p = sub.add_parser("globloc", help="per-frame costs of Gist retrieval, ORB + PnP, Scan2Map, rendering")
    p.add_argument("--exp", default="globloc_corridor")
    p.add_argument("--device", default="cpu")
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--keyframes", type=int, default=1000)
    p.add_argument("--render-batch", type=int, default=256)
    p.add_argument(
        "--render-only", action="store_true", help="rendering and the Gist only (no OpenCV needed, e.g. on a GPU box)"
    )
    p.add_argument("--out", default="outputs/bench")


def run_globloc_bench(a) -> dict:
    cfg = compose_config([f"+exp={a.exp}", f"device={a.device}"])
    device = pick_device(a.device)
    g, s = cfg.globloc, cfg.sim
    world = world_of(cfg)
    look = appearance(world, s.seed, g.lookalike_share)
    grid, origin = grid_of(world, g.map_resolution_m)
    camera = Camera(world.segments, look, device=device)
    mapping = follow(waypoints(world, np.random.default_rng(s.seed), 1.0), s.speed_mps, s.turn_rate_rps, s.rate_hz)
    kf = keyframe_indices(mapping, g.keyframe_every_m, np.radians(g.keyframe_every_deg))
    kf = np.resize(kf, a.keyframes)  # cut or repeat to the requested database size
    camera.render(mapping[:4])  # compile / warm up
    t = time.perf_counter()
    rgb, depth = camera.render(mapping[kf], Session(seed=s.seed), batch=a.render_batch)
    render_s = time.perf_counter() - t
    gist = Gist(
        tuple(g.gist_size),
        g.gist_blocks,
        tuple(g.gist_orientations),
        device="cuda" if device.startswith("cuda") else "cpu",
    )
    t = time.perf_counter()
    db = build_database(mapping[kf], rgb, depth, gist)
    db_s = time.perf_counter() - t
    import warp as wp

    cams = compose_se2(mapping[kf][: a.render_batch], camera.T_base_cam)
    camera.kernel.render(cams, on_device=True)
    wp.synchronize_device(device)
    t = time.perf_counter()
    for _ in range(5):
        camera.kernel.render(cams, on_device=True)
    wp.synchronize_device(device)
    device_fps = 5 * len(cams) / (time.perf_counter() - t)
    print(
        f"rendering kept on {device}: {device_fps:.0f} frames/s in batches of {len(cams)} "
        f"(with the copy to host memory: {len(kf) / render_s:.0f})"
    )
    base = {
        "exp": a.exp,
        "device": device,
        "host": platform.processor() or platform.machine(),
        "keyframes": len(db),
        "image": f"{camera.size_hw[1]}x{camera.size_hw[0]}",
        "render_fps": len(kf) / render_s,
        "render_fps_on_device": device_fps,
        "database_build_s": db_s,
    }
    if a.render_only:
        one = rgb[:1]
        describe(one, gist)
        t = time.perf_counter()
        for _ in range(20):
            describe(one, gist)
        row = {**base, "gist_ms": 1e3 * (time.perf_counter() - t) / 20}
        print(
            f"rendering on {device}: {row['render_fps']:.0f} frames/s ({row['image']}, batches of {a.render_batch}); "
            f"Gist of one query {row['gist_ms']:.1f} ms; database of {len(db)} built in {db_s:.1f} s"
        )
        return _save(a, row, record_path("", "globloc", device, "render", a.exp).name)
    hyp = Hypotheses(cfg, db, camera, Scan2Map(grid, origin, g.map_resolution_m, g.scan2map))
    st = make_stream(cfg, world, look, np.random.default_rng(1), 0, device)
    frames = min(a.frames, len(st.cam_idx))
    hyp(st.rgb[0], st.ranges[st.cam_idx[0]])  # warm up
    hyp.timing = {k: 0.0 for k in hyp.timing}
    candidates = 0
    t = time.perf_counter()
    for j in range(frames):
        candidates += len(hyp(st.rgb[j], st.ranges[st.cam_idx[j]]))
    decision_ms = 1e3 * (time.perf_counter() - t) / frames
    per = {k: 1e3 * v / frames for k, v in hyp.timing.items() if k != "frames"}
    pnp_tries = frames * g.clusters * g.pnp_per_cluster
    s2m = Scan2Map(grid, origin, g.map_resolution_m, g.scan2map)
    poses = mapping[kf[:100]]
    t = time.perf_counter()
    s2m(poses, (s.laser_x_m, 0.0, 0.0), st.ranges[0], laser_angles(cfg))
    s2m_ms = 1e3 * (time.perf_counter() - t) / len(poses)
    row = {
        **base,
        "decision_ms": decision_ms,
        "gist_ms": per["gist"],
        "retrieval_ms": per["retrieval"],
        "pnp_ms_per_keyframe": 1e3 * hyp.timing["pnp"] / max(pnp_tries, 1),
        "scan2map_ms_per_candidate": s2m_ms,
        "frames": frames,
        "accepted_candidates_per_frame": candidates / frames,
    }
    print(f"lidar + camera relocalization on {device}, {a.exp}, {len(db)} keyframes, images {row['image']}")
    print(
        "| render (frames/s) | Gist of a query (ms) | retrieval (ms) | ORB + PnP per keyframe (ms) | "
        "Scan2Map per candidate (ms) | whole decision (ms) |\n|---|---|---|---|---|---|"
    )
    print(
        f"| {row['render_fps']:.0f} | {row['gist_ms']:.1f} | {row['retrieval_ms']:.2f} | {row['pnp_ms_per_keyframe']:.1f} "
        f"| {row['scan2map_ms_per_candidate']:.3f} | {row['decision_ms']:.1f} |"
    )
    return _save(a, row, record_path("", "globloc", device, a.exp).name)


def _save(a, row: dict, name: str) -> dict:
    out = Path(a.out) / name
    write_json(out, {"argv": vars(a), "rows": [row]})
    print(f"-> {out}")
    return row
