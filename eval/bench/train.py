"""``python -m eval.bench train [--device cuda] [--batch 1024] [--samples 256] [--steps 10]``
``python -m eval.bench train --exp fr079 --init outputs/fr079/train/<run>/nof.pt [--variants ...] [--profile]``:
the training step itself (``Trainer.step``) on the experiment's training rays, for each variant of the
``train=`` settings (default: ``sampler=uniform`` against ``sampler=occupancy``) side by side, from a trained
NOF (an untrained one is occupied everywhere, so its grid skips nothing).
(``python -m eval.bench mcl ...``: the MCL step, eval/bench/mcl.py; ``python -m eval.bench slam ...``: the
GMapping RBPF, eval/bench/slam.py; ``globloc``: eval/bench/globloc.py.)

Side-by-side speed of NOF training on one device, in one run: rays/s of a whole training step
(encode + MLP forward, composite, loss, backward, Adam) with the Warp renderer and with
``render=torch_ref``, for the paper's network (and, with --amp, bf16 autocast), plus the compositing alone
(forward + backward on random occupancies). Prints a table and writes outputs/bench/train-<device>.json.
Absolute times count only from a GPU; on a CPU read the ratios.
"""

from __future__ import annotations

import platform
from pathlib import Path

import torch

from eval.bench.timing import record_path, repeated, step_ms_fields
from irmcl_warp.config import ModelConfig
from irmcl_warp.nof.model import NOF
from irmcl_warp.nof.render import make_renderer, render_rays, sample_depths
from irmcl_warp.nof.trainer import opacity_regulariser
from irmcl_warp.services.outputs import write_json

MODELS = {
    "paper": ModelConfig(),
    "cpu": ModelConfig(width=128, depth=4, skip_after=2),
    "quick": ModelConfig(width=64, depth=4, skip_after=2, num_freqs=8),
}


def _sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize()


def _timing(r: dict, batch: int) -> dict:
    """The median of the repeats (and their spread) in ms per step, and rays/s at the median."""
    return {**step_ms_fields(r), "rays_per_s": batch / r["median"]}


def bench_step(model_name, renderer_name, batch, samples, steps, device, amp=False, repeats=5) -> dict:
    torch.manual_seed(0)
    model = NOF(MODELS[model_name]).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=1e-4, weight_decay=1e-3)
    render = make_renderer(renderer_name)
    origins = torch.rand(batch, 2, device=device) * 20 - 10
    angle = torch.rand(batch, device=device) * 6.283
    dirs = torch.stack([torch.cos(angle), torch.sin(angle)], -1)
    target = torch.rand(batch, device=device) * 10 + 0.5

    def step():
        z = sample_depths(batch, samples, 0.02, 40.0, True, device=device)
        ctx = torch.autocast("cuda", dtype=torch.bfloat16) if amp else torch.autocast(device.type, enabled=False)
        with ctx:
            pred, _, p = render_rays(model, render, origins, dirs, z)
        loss = torch.nn.functional.smooth_l1_loss(pred, target) + 1e-5 * opacity_regulariser(p)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    r = repeated(step, lambda: _sync(device), steps, repeats)
    return {
        "what": "train step",
        "model": model_name,
        "renderer": renderer_name,
        "amp": "bf16" if amp else "off",
        "batch_rays": batch,
        "samples": samples,
        **_timing(r, batch),
    }


def bench_composite(renderer_name, batch, samples, steps, device, repeats=5) -> dict:
    torch.manual_seed(0)
    p = torch.rand(batch, samples, device=device).pow(3).requires_grad_()
    z = sample_depths(batch, samples, 0.02, 40.0, True, device=device)
    render = make_renderer(renderer_name)
    g = torch.randn(batch, device=device)

    def step():
        p.grad = None
        r, _ = render(p, z)
        (r * g).sum().backward()

    r = repeated(step, lambda: _sync(device), steps, repeats)
    return {
        "what": "composite fwd+bwd",
        "model": "-",
        "renderer": renderer_name,
        "amp": "off",
        "batch_rays": batch,
        "samples": samples,
        **_timing(r, batch),
    }


def bench_trainer_steps(a, device) -> list[dict]:
    """Trainer.step on real rays for each variant; the grid is read from the trained field before timing
    (the warm-up covers one grid period and, with train.compile, the compilation)."""
    import tempfile

    from irmcl_warp.config import ModelConfig, compose_config
    from irmcl_warp.nof.checkpoint import load_nof
    from irmcl_warp.nof.trainer import Trainer
    from irmcl_warp.services.data import far_bound_m, prepare_beams

    rows, sets = [], None
    for variant in a.variants:
        sets_ = [f"train.{kv}" for kv in variant.split(",")]
        cfg = compose_config(
            # the preset's batch unless --batch is given (until the twenty-third session, a default of 1024 timed other steps than
            # the presets train: 4096 rays)
            [
                f"+exp={a.exp}",
                f"train={a.preset}",
                *sets_,
                *([f"train.batch_rays={a.batch[0]}"] if a.batch else []),
                f"device={device}",
            ]
        )
        sets = sets or {"train": prepare_beams(cfg)["train"]}  # the rays do not depend on train= settings
        model, meta = load_nof(a.init, device)
        model = getattr(model, "field", model)  # trained through its grid (MaskedField): the variant's grid decides
        if ModelConfig(**meta["model_config"]) != ModelConfig(**cfg.model):
            raise ValueError(f"{a.init}: made with another network than model= of +exp={a.exp}")
        torch.manual_seed(0)
        with tempfile.TemporaryDirectory() as tmp:
            tr = Trainer(
                model.train(),
                sets,
                cfg.train,
                cfg.render,
                cfg.render.near_m,
                far_bound_m(cfg),
                device,
                Path(tmp),
                "bench",
                lambda m: {},
                {},
            )
            gen = torch.Generator().manual_seed(0)
            batches = [
                torch.randint(len(tr.ranges), (cfg.train.batch_rays,), generator=gen).to(device) for _ in range(a.steps)
            ]
            it = iter(range(1 << 30))

            def step():
                tr.step_in_epoch = next(it)  # the grid is read every train.grid_every steps, as in training
                tr.step(batches[tr.step_in_epoch % len(batches)])

            try:
                r = repeated(step, lambda: _sync(device), a.steps, a.repeats, warmup=max(cfg.train.grid_every, 3))
            except Exception as e:  # e.g. train.compile without a working compiler on this machine
                print(f"{variant}: failed ({type(e).__name__}: {str(e)[:300]})")
                continue
            kept = float(torch.stack(tr.kept).float().mean()) if tr.kept else float(cfg.train.num_samples)
            read = float(torch.stack(tr.read).float().mean()) if tr.read else 0.0
            if a.profile and variant == a.variants[-1]:
                from torch.profiler import ProfilerActivity, profile

                acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda" else [])
                with profile(activities=acts) as prof:
                    for _ in range(a.steps):
                        step()
                    _sync(device)
                key = "cuda_time_total" if device.type == "cuda" else "cpu_time_total"
                print(prof.key_averages().table(sort_by=key, row_limit=25))
        flop = model.flops_per_point() * (3 * kept + read) * cfg.train.batch_rays
        rows.append(
            {
                "what": f"Trainer.step {a.exp}",
                "model": a.preset,
                "renderer": f"{cfg.render.name}, {variant}",
                "amp": cfg.train.amp,
                "batch_rays": cfg.train.batch_rays,
                "samples": cfg.train.num_samples,
                "samples_with_grad": kept,
                "samples_read": read,
                "mlp_gflop_per_step": flop / 1e9,
                **_timing(r, cfg.train.batch_rays),
            }
        )
        rows[-1]["mlp_tflop_per_s"] = flop / (1e-3 * rows[-1]["step_ms"]) / 1e12
    for x in rows:
        print(
            f"{x['renderer']}: {x['step_ms']:.2f} ms/step [{x['step_ms_min']:.2f}-{x['step_ms_max']:.2f}], "
            f"{x['samples_with_grad']:.1f} samples per beam with gradient, {x['samples_read']:.1f} read without, "
            f"{x['mlp_gflop_per_step']:.0f} GFLOP per step, {x['mlp_tflop_per_s']:.1f} TFLOP/s"
        )
    return rows


def run_train_bench(a) -> list[dict]:
    device = torch.device(a.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    if device.type == "cuda" and a.tf32:
        torch.backends.cuda.matmul.allow_tf32 = True
    if a.exp:
        rows = bench_trainer_steps(a, device)
        name = torch.cuda.get_device_name() if device.type == "cuda" else platform.processor() or "cpu"
        out = record_path(a.out, "train", device.type, "steps", a.exp)
        write_json(
            out, {"device": str(device), "device_name": name, "torch": torch.__version__, "argv": vars(a), "rows": rows}
        )
        print(f"-> {out}")
        return rows
    rows = []
    for batch in a.batch or [1024]:
        for r in ("warp", "torch_ref"):
            rows.append(bench_composite(r, batch, a.samples, max(a.steps, 5), device, a.repeats))
        for r in ("warp", "torch_ref"):
            rows.append(bench_step(a.model, r, batch, a.samples, a.steps, device, repeats=a.repeats))
        if a.amp and device.type == "cuda":
            for r in ("warp", "torch_ref"):
                rows.append(bench_step(a.model, r, batch, a.samples, a.steps, device, amp=True, repeats=a.repeats))
    name = torch.cuda.get_device_name() if device.type == "cuda" else platform.processor() or "cpu"
    print(
        f"\nNOF training speed on {name} ({device}), torch {torch.__version__}, tf32 {a.tf32 and device.type == 'cuda'}"
    )
    print(
        f"| what | model | renderer | amp | batch | samples | ms/step: median of {a.repeats} [min-max] | rays/s |\n"
        "|---|---|---|---|---|---|---|---|"
    )
    for x in rows:
        print(
            f"| {x['what']} | {x['model']} | {x['renderer']} | {x['amp']} | {x['batch_rays']} | {x['samples']} | "
            f"{x['step_ms']:.2f} [{x['step_ms_min']:.2f}-{x['step_ms_max']:.2f}] | {x['rays_per_s']:,.0f} |"
        )
    out = record_path(a.out, "train", device.type)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(
        out, {"device": str(device), "device_name": name, "torch": torch.__version__, "argv": vars(a), "rows": rows}
    )
    print(f"-> {out}")
    return rows


def add_parser(sub) -> None:
    t = sub.add_parser("train", help="rays/s of a NOF training step, Warp vs torch_ref renderer")
    t.add_argument("--device", default=None)
    t.add_argument("--model", default="paper", choices=sorted(MODELS))
    t.add_argument(
        "--batch", type=int, nargs="+", default=None, help="rays per step (default 1024; with --exp the preset's)"
    )
    t.add_argument("--samples", type=int, default=256)
    t.add_argument("--steps", type=int, default=10)
    t.add_argument("--amp", action="store_true", help="also time bf16 autocast (CUDA only)")
    t.add_argument("--tf32", action="store_true")
    t.add_argument("--repeats", type=int, default=5, help="timings of --steps steps each; the table shows their median")
    t.add_argument("--out", default="outputs/bench")
    t.add_argument("--exp", default=None, help="time Trainer.step on this experiment's rays (uniform vs occupancy)")
    t.add_argument("--init", default=None, help="with --exp: the trained nof.pt the steps start from")
    t.add_argument("--preset", default="guided", help="with --exp: the train= preset the variants change")
    t.add_argument("--profile", action="store_true", help="with --exp: torch profile of the last variant's steps")
    t.add_argument(
        "--variants",
        nargs="+",
        default=["sampler=uniform", "sampler=occupancy"],
        help="with --exp: train settings per variant, comma-separated (e.g. sampler=occupancy,grid_end=none)",
    )
