"""``WEIGHTING["nof_direct"]``: IR-MCL's observation model on the NOF itself, no grid. It lives beside the
NOF because it runs the torch MLP; importing this module registers it (services.filters does when
``mcl.weighting=nof_direct``). The compositing and the likelihood are the Warp kernels of kernels/render.py
and kernels/weighting.py; tests/test_weighting.py checks it against a torch twin of the whole model."""

from __future__ import annotations

import torch
import warp as wp

from irmcl_warp.nof.checkpoint import load_nof_for
from irmcl_warp.kernels import RENDER, WEIGHTING, pick_device
from irmcl_warp.kernels.weighting import make_likelihood_kernel


class NofDirect:
    """``nof_direct``: IR-MCL's observation model on the NOF itself, no grid (for small particle sets, and as
    the ablation of the NOG's nearest-node approximation). Per call: the sample points of every particle
    and beam (torch), the MLP in chunks, compositing by the Warp ``composite`` kernel (kernels/render.py,
    normalised as in training), then |r - m| per valid beam and the Gaussian on its mean, as
    ``nog_raymarch``. The particle arrays stay on their device (zero-copy ``wp.to_torch``)."""

    def __init__(
        self,
        checkpoint=None,
        model=None,
        num_particles: int = 1000,
        num_beams: int = 32,
        num_samples: int = 256,
        near_m: float = 0.02,
        far_m: float = 40.0,
        sigma_m: float = 0.5,
        chunk_rays: int = 4096,
        device: str = "auto",
    ):
        self.device = pick_device(device)
        self.torch_device = torch.device("cuda" if self.device.startswith("cuda") else "cpu")
        if model is None:
            if checkpoint is None:
                raise ValueError("nof_direct: give a NOF checkpoint (nof.pt) or a model")
            model, _ = load_nof_for(checkpoint, far_m, self.torch_device)
        self.model = model.to(self.torch_device).eval()
        self.num_beams, self.chunk = num_beams, int(chunk_rays)
        self.z = torch.linspace(near_m, far_m, num_samples, device=self.torch_device)
        self.compositor = RENDER.build("composite", normalize=True)
        self.likelihood_kernel = make_likelihood_kernel(sigma_m)

    def render(self, particles: wp.array, T_base_laser, angles: wp.array):
        """Rendered ranges [P, B] as a torch tensor."""
        with torch.no_grad():
            p = wp.to_torch(particles).to(self.torch_device).double()
            a = wp.to_torch(angles).to(self.torch_device).double()
            tx, ty, tt = map(float, T_base_laser)
            c, s = torch.cos(p[:, 2]), torch.sin(p[:, 2])
            origin = torch.stack([p[:, 0] + c * tx - s * ty, p[:, 1] + s * tx + c * ty], -1)  # [P, 2]
            yaw = p[:, 2:3] + tt + a[None, :]  # [P, B]
            dirs = torch.stack([torch.cos(yaw), torch.sin(yaw)], -1).reshape(-1, 2).float()
            origins = origin[:, None, :].expand(-1, a.shape[0], -1).reshape(-1, 2).float()
            out = torch.empty(origins.shape[0], device=self.torch_device)
            z = self.z
            for k in range(0, origins.shape[0], self.chunk):
                o, d = origins[k : k + self.chunk], dirs[k : k + self.chunk]
                occ = self.model((o[:, None, :] + d[:, None, :] * z[None, :, None]).reshape(-1, 2))
                occ = occ.float().reshape(o.shape[0], z.shape[0])
                out[k : k + self.chunk] = self.compositor.forward(occ, z.expand(o.shape[0], -1))[0]
            return out.reshape(p.shape[0], a.shape[0])

    def __call__(
        self, particles: wp.array, T_base_laser, angles: wp.array, measured: wp.array, log_weights: wp.array
    ) -> None:
        if angles.shape[0] != self.num_beams or measured.shape[0] != self.num_beams:
            raise ValueError(
                f"nof_direct: {measured.shape[0]} measured ranges / {angles.shape[0]} angles, "
                f"built for {self.num_beams} beams"
            )
        rendered = self.render(particles, T_base_laser, angles).contiguous().to(wp.device_to_torch(self.device))
        wp.launch(
            self.likelihood_kernel,
            particles.shape[0],
            [wp.from_torch(rendered), measured, log_weights],
            device=self.device,
        )


@WEIGHTING.register("nof_direct")
def make_nof_direct(**settings) -> NofDirect:
    return NofDirect(**settings)
