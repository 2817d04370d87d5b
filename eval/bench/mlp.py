"""``python -m eval.bench mlp [--device cuda] [--points 348160 503808] [--forms eager compiled ...]``: what the NOF's
MLP work of one training step costs at best on this device (issue 36, "the MLP phase at >= 30 % of the GPU's dense
bf16 peak"; "a NOF in ten seconds").

A training step of `train=minute` sends about 85 samples per beam x 4096 beams through the paper's network with
gradient on fr079 (123 on intel; docs/benchmarks.md, fourteenth session), 3,300 steps in all. Here that many random
points go through the network forward and backward and Adam steps, with nothing else of the step (no sampling, no
compositing, no grid), in several forms, side by side in one run:

* ``eager``: the module as the trainer runs it (bf16 autocast, batch norm, fused Adam);
* ``compiled``: the same under ``torch.compile`` with a fixed number of points (what fixed-size batches would allow);
* ``graphed``: ``compiled`` with ``mode="reduce-overhead"`` (CUDA graphs: no launch cost left);
* ``autotune``: ``compiled`` with ``mode="max-autotune-no-cudagraphs"``: inductor times Triton templates for each
  matmul and may fuse the batch norm's and ReLU's pointwise work into them (what ``train.compile_mode`` of that name
  does inside ``train.step_graph``; the first call autotunes, minutes);
* ``no_bn``: the paper's linear layers and ReLUs without batch norm, compiled: the floor of this network's shape
  (its matmuls, whose width of 256 keeps them bound by memory as much as by arithmetic).

Beside the forms it prints this network's roofline: the bytes a point's forward and backward must move at least
(``min_bytes_per_point``: every linear layer reads its input and writes its output once forward, and backward reads
its output gradient twice and its input once and writes its input gradient, all bf16, with batch norm and ReLU fused
away), so the share of the peak no kernel can pass on a device of ``--bandwidth-tbs``.

Each form's row: ms per step (median of ``--repeats`` timings [min-max]), the MLP's TFLOP/s (3 x the forward's
multiply-adds x 2 per point: forward, and backward for inputs and weights), its share of ``--peak-tflops`` (the
H100 SXM's dense bf16 figure by default), and the 3,300 steps' time at that rate. Prints a table and writes
``<out>/mlp-<device>.json``. Absolute times count only from a GPU.
"""

from __future__ import annotations

import platform

import torch
from torch import nn

from eval.bench.timing import record_path, repeated, step_ms_fields
from irmcl_warp.config import ModelConfig
from irmcl_warp.nof.model import NOF
from irmcl_warp.services.outputs import write_json

FORMS = ("eager", "compiled", "graphed", "autotune", "no_bn")
STEPS_PER_RUN = 3300  # train=minute: 10 epochs x 330 steps


def without_batch_norm(model: NOF) -> NOF:
    """The same network with every batch norm replaced by the identity (its linear layers and ReLUs kept)."""
    for seq in (model.head, model.tail):
        for block in seq:
            block[1] = nn.Identity()
    return model


def mlp_step(form: str, points: int, device: torch.device, seed: int = 0):
    """(one training step of the MLP alone for ``points`` random points, the model): forward under bf16 autocast on
    a GPU, a mean-absolute loss, backward, Adam."""
    torch.manual_seed(seed)
    model = NOF(ModelConfig()).to(device)
    if form == "no_bn":
        model = without_batch_norm(model)
    cuda = device.type == "cuda"
    opt = torch.optim.Adam(model.parameters(), lr=1e-4, weight_decay=1e-3, fused=True if cuda else None)
    net = model
    if form in ("compiled", "no_bn"):
        net = torch.compile(model, dynamic=False)
    elif form == "graphed":
        net = torch.compile(model, dynamic=False, mode="reduce-overhead")
    elif form == "autotune":
        net = torch.compile(model, dynamic=False, mode="max-autotune-no-cudagraphs")
    xy = torch.rand(points, 2, device=device) * 40 - 20
    target = torch.rand(points, device=device)

    def step():
        if form == "graphed":
            torch.compiler.cudagraph_mark_step_begin()  # the last step's outputs may be overwritten
        ctx = torch.autocast("cuda", dtype=torch.bfloat16) if cuda else torch.autocast("cpu", enabled=False)
        with ctx:
            loss = (net(xy).float() - target).abs().mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    return step, model


def flop_per_step(model: NOF, points: int) -> float:
    """3 x the forward's multiply-adds x 2 (``NOF.flops_per_point``) per point: forward, backward to the inputs and
    to the weights."""
    return 3.0 * model.flops_per_point() * points


def min_bytes_per_point(model: NOF) -> int:
    """The least a point's training pass moves through memory (bf16, 2 bytes a value): per linear layer, forward
    reads the input and writes the output (in + out), backward reads the output gradient for the input gradient and
    again for the weight gradient, reads the input, writes the input gradient (2 in + 2 out). Batch norm, ReLU and
    the encoding are taken as fused into the matmuls (their statistics cost nothing), so no real kernel moves less."""
    return sum(2 * 3 * (m.in_features + m.out_features) for m in model.modules() if isinstance(m, nn.Linear))


def roofline_share(model: NOF, peak_tflops: float, bandwidth_tbs: float) -> float:
    """The share of ``peak_tflops`` this network's training pass can reach at most when bound by memory
    (``bandwidth_tbs``): its FLOP per byte moved at least, times the bandwidth, over the peak (1 when bound by
    arithmetic)."""
    intensity = flop_per_step(model, 1) / min_bytes_per_point(model)
    return min(1.0, intensity * bandwidth_tbs / peak_tflops)


def bench_mlp(form: str, points: int, device: torch.device, steps: int, repeats: int, peak_tflops: float) -> dict:
    step, model = mlp_step(form, points, device)
    sync = (lambda: torch.cuda.synchronize(device)) if device.type == "cuda" else (lambda: None)
    r = repeated(step, sync, steps, repeats, warmup=3)
    flop = flop_per_step(model, points)
    tflops = flop / r["median"] / 1e12
    return {
        "form": form,
        "points": points,
        **step_ms_fields(r),
        "gflop_per_step": flop / 1e9,
        "tflop_per_s": tflops,
        "share_of_peak": tflops / peak_tflops,
        "run_s_at_this_rate": STEPS_PER_RUN * r["median"],
    }


def run_mlp_bench(a) -> list[dict]:
    device = torch.device(a.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    if device.type == "cuda":
        torch.backends.cuda.matmul.allow_tf32 = True
    rows = []
    for points in a.points:
        for form in a.forms:
            rows.append(bench_mlp(form, points, device, a.steps, a.repeats, a.peak_tflops))
            x = rows[-1]
            print(f"{form} {points}: {x['step_ms']:.2f} ms, {x['tflop_per_s']:.0f} TFLOP/s", flush=True)
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else platform.processor() or "cpu"
    model = NOF(ModelConfig())
    ceiling = roofline_share(model, a.peak_tflops, a.bandwidth_tbs)
    roof = {
        "min_bytes_per_point": min_bytes_per_point(model),
        "flop_per_point": flop_per_step(model, 1),
        "bandwidth_tbs": a.bandwidth_tbs,
        "ceiling_share_of_peak": ceiling,
    }
    print(
        f"\nRoofline: {roof['flop_per_point'] / 1e6:.2f} MFLOP and at least {roof['min_bytes_per_point']:,} bytes per "
        f"point ({roof['flop_per_point'] / roof['min_bytes_per_point']:.0f} FLOP/byte); at {a.bandwidth_tbs} TB/s no "
        f"kernel passes {100 * ceiling:.0f} % of {a.peak_tflops:.0f} TFLOP/s"
    )
    print(f"\nThe NOF's MLP work of a training step on {name} ({device}), torch {torch.__version__}, bf16 autocast")
    print(
        f"| form | points | ms/step: median of {a.repeats} [min-max] | GFLOP/step | TFLOP/s | share of "
        f"{a.peak_tflops:.0f} | {STEPS_PER_RUN} steps (s) |\n|---|---|---|---|---|---|---|"
    )
    for x in rows:
        print(
            f"| {x['form']} | {x['points']:,} | {x['step_ms']:.2f} [{x['step_ms_min']:.2f}-{x['step_ms_max']:.2f}] | "
            f"{x['gflop_per_step']:.0f} | {x['tflop_per_s']:.0f} | {100 * x['share_of_peak']:.1f} % | "
            f"{x['run_s_at_this_rate']:.1f} |"
        )
    out = record_path(a.out, "mlp", device.type)
    write_json(
        out,
        {
            "device": str(device),
            "device_name": name,
            "torch": torch.__version__,
            "argv": vars(a),
            "roofline": roof,
            "rows": rows,
        },
    )
    print(f"-> {out}")
    return rows


def add_parser(sub) -> None:
    t = sub.add_parser("mlp", help="the NOF's MLP work of one training step alone, in several forms")
    t.add_argument("--device", default=None)
    t.add_argument(
        "--points",
        type=int,
        nargs="+",
        default=[4096 * 85, 4096 * 123],
        help="points with gradient per step (default: train=minute's on fr079 and intel)",
    )
    t.add_argument("--forms", nargs="+", default=list(FORMS), choices=FORMS)
    t.add_argument("--steps", type=int, default=20)
    t.add_argument("--repeats", type=int, default=5)
    t.add_argument("--peak-tflops", type=float, default=989.0, help="the device's dense bf16 peak (H100 SXM: 989)")
    t.add_argument(
        "--bandwidth-tbs", type=float, default=3.35, help="the device's memory bandwidth (H100 SXM: 3.35, H200: 4.8)"
    )
    t.add_argument("--out", default="outputs/bench")
