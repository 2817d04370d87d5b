"""Our driver for the authors' scan-synthesis evaluation (run with their Python, in their tree): their dataset
class reads the test split, their ``render_rays`` renders it with their network, and their ``error_metrics``
(eval.py; open3d for the Chamfer distance) scores each scan. Their eval.py prints the means with two decimals;
this prints them, and the per-scan values, with full precision as JSON.

    python irmcl_eval_driver.py ROOT_DIR CKPT OUT_JSON      (cwd: their source tree)
"""

import hashlib
import json
import sys

import torch

from eval import error_metrics  # their eval.py (this runs in their tree, where "eval" is that file)
from nof.dataset import IPB2DMapping
from nof.networks import NOF, Embedding
from nof.nof_utils import decode_batch, load_ckpt
from nof.render import render_rays

root, ckpt, out = sys.argv[1:4]
device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
embedding = Embedding(in_channels=2, N_freq=10)
model = NOF(feature_size=256, in_channels_xy=2 + 2 * 10 * 2, use_skip=True)
load_ckpt(model, ckpt, model_name="nof")
model.to(device).eval()
dataset = IPB2DMapping(root, split="test")
rows = []
for k in range(len(dataset)):
    data = {key: v.unsqueeze(0) for key, v in dataset[k].items()}  # as their DataLoader of batch size 1 gives it
    rays, ranges = decode_batch(data)
    rays, ranges, valid = rays.squeeze().to(device), ranges.squeeze().to(device), data["valid_mask_gt"].squeeze()
    with torch.no_grad():  # their fr079.sh evaluation settings
        pred = render_rays(
            model=model,
            embedding_xy=embedding,
            rays=rays,
            N_samples=256,
            use_disp=False,
            perturb=0,
            noise_std=0,
            chunk=92160,
        )["depth"].cpu()
    rows.append([float(v) for v in error_metrics(pred, ranges.cpu(), rays.cpu(), valid)])
    if k % 50 == 0:
        print(f"scan {k} of {len(dataset)}", flush=True)
mean = torch.tensor(rows).mean(0).tolist()
json.dump(
    {
        "checkpoint_sha256": hashlib.sha256(open(ckpt, "rb").read()).hexdigest(),
        "scans": len(rows),
        "mae_m": mean[0],
        "accuracy_pct": mean[1],
        "chamfer_m": mean[2],
        "fscore_pct": 100 * mean[3],
        "per_scan": rows,
    },
    open(out, "w"),
)
