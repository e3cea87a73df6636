#!/usr/bin/env python3
"""Writes the PyTorch <-> C++ parity fixture of tests/model (docs/model-file.md, "Parity fixture").

  /usr/bin/python3 training/export_fixture.py [--out-dir tests/data]

tiny_model.safetensors: a seeded random MlpWin with the real D = 191 and W=4, E=8, H=16, L=1, TE=64,
  T=10; every parameter (LayerNorm gains and biases included) drawn at random so that a mixed-up
  tensor changes the output.
tiny_model_io.safetensors: the same container; metadata "cases" (JSON) lists the cases, tensors hold
  their inputs and PyTorch's outputs:
    forward.<i>.x, forward.<i>.m, forward.<i>.out  (W, D); step in cases["forward"][i]["t"]
    ddim.<i>.obs, ddim.<i>.mask, ddim.<i>.noise, ddim.<i>.out  (W, D); cases["ddim"][i] has K,
      guidance, eta (0) and the timesteps.
tiny_tcn.safetensors, tiny_tcn_io.safetensors: the same for a seeded random TcnCausal (tcn-v1) with
  D = 191 and W=10, C=16, K=3, L=3, R=2 (dilations 1, 2, 1: receptive field 9 <= W), TE=64, T=10; two
  forward cases and one DDIM run.
tiny_tcnmlp.safetensors, tiny_tcnmlp_io.safetensors: the same for a seeded random TcnMlp (tcnmlp-v1)
  with D = 191 and W=10, N=4, E=8, H=16, L=1, C=16, K=3, B=3, R=2 (receptive field 9 <= W), TE=64,
  T=10.
Deterministic: re-running rewrites identical files.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import model_net as mn  # noqa: E402

W, D, E, H, L, TE, T = 4, 191, 8, 16, 1, 64, 10
TCN = {"W": 10, "D": D, "C": 16, "K": 3, "L": 3, "R": 2, "TE": 64, "T": 10}
TCNMLP = {"W": 10, "D": D, "N": 4, "E": 8, "H": 16, "L": 1, "C": 16, "K": 3, "B": 3, "R": 2, "TE": 64, "T": 10}


def randomise(net: torch.nn.Module, g: torch.Generator) -> None:
    with torch.no_grad():
        for name, p in net.named_parameters():
            if "norm" in name and name.endswith("weight"):
                p.copy_(1.0 + 0.3 * torch.randn(p.shape, generator=g))
            elif name.endswith("weight"):
                p.copy_(torch.randn(p.shape, generator=g) * (1.5 / math.sqrt(math.prod(p.shape[1:]))))
            else:
                p.copy_(0.3 * torch.randn(p.shape, generator=g))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out-dir", default=os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                                      "tests", "data"))
    a = ap.parse_args()
    torch.set_num_threads(1)
    g = torch.Generator().manual_seed(20240611)
    net = mn.MlpWin(W, D, E=E, H=H, L=L, TE=TE, T=T)
    randomise(net, g)
    net.eval()
    mean = torch.randn(D, generator=g) * 0.1
    std = 0.5 + torch.rand(D, generator=g)
    ab = mn.cosine_alpha_bars(T)
    skeleton = mn.skeleton_from_bvh(os.path.join(a.out_dir, "walk_60.bvh"))
    model_path = os.path.join(a.out_dir, "tiny_model.safetensors")
    mn.write_model(model_path, net, mean, std, ab, skeleton,
                   {"provenance": {"data": "none: seeded random parameters (training/export_fixture.py)",
                                   "command": "python3 training/export_fixture.py"}})

    # Masks: random entries; nothing observed; a few feature columns in every frame plus whole frames.
    masks = [(torch.rand(W, D, generator=g) < 0.4).float(), torch.zeros(W, D), torch.zeros(W, D)]
    masks[2][:, 36:54] = 1.0
    masks[2][:, 81:90] = 1.0
    masks[2][0, :] = 1.0
    tensors: dict[str, torch.Tensor] = {}
    cases: dict[str, list] = {"forward": [], "ddim": []}
    with torch.no_grad():
        for i, (t, m) in enumerate(zip([0, 5, 9], masks)):
            obs = torch.randn(W, D, generator=g) * 1.5
            x = m * obs + (1 - m) * torch.randn(W, D, generator=g)
            out = net(x[None], m[None], torch.tensor([t]))[0]
            tensors.update({f"forward.{i}.x": x, f"forward.{i}.m": m, f"forward.{i}.out": out})
            cases["forward"].append({"t": t})
        for i, (K, s, m) in enumerate([(4, 1.0, masks[2]), (3, 2.5, masks[0])]):
            obs = torch.randn(W, D, generator=g)
            noise = torch.randn(W, D, generator=g)
            out = mn.ddim_sample(net, obs[None], m[None], ab, K, None, guidance=s, noise=noise[None])[0]
            tensors.update({f"ddim.{i}.obs": obs, f"ddim.{i}.mask": m, f"ddim.{i}.noise": noise, f"ddim.{i}.out": out})
            cases["ddim"].append({"K": K, "guidance": s, "eta": 0.0, "timesteps": mn.ddim_timesteps(T, K)})
    io_path = os.path.join(a.out_dir, "tiny_model_io.safetensors")
    mn.write_tensor_file(io_path, tensors, {"cases": json.dumps(cases), "model": "tiny_model.safetensors",
                                            "written_by": "training/export_fixture.py"})
    c = TCN
    tcn = mn.TcnCausal(c["W"], c["D"], C=c["C"], K=c["K"], L=c["L"], R=c["R"], TE=c["TE"], T=c["T"])
    temporal = write_temporal(a.out_dir, skeleton, "tiny_tcn", tcn, 20261202)
    tcnmlp = mn.TcnMlp(**TCNMLP)
    temporal += write_temporal(a.out_dir, skeleton, "tiny_tcnmlp", tcnmlp, 20261203)
    for p in (model_path, io_path) + temporal:
        print(f"wrote {p} ({os.path.getsize(p)} bytes)")


def write_temporal(out_dir: str, skeleton: dict, name: str, net: torch.nn.Module, seed: int) -> tuple[str, str]:
    """<name>.safetensors and <name>_io.safetensors for a temporal network (its own generator, so that
    each fixture stays as it was when another is added)."""
    g = torch.Generator().manual_seed(seed)
    assert net.receptive_field() <= net.W
    randomise(net, g)
    net.eval()
    Wt, Tt = net.W, net.T
    mean = torch.randn(D, generator=g) * 0.1
    std = 0.5 + torch.rand(D, generator=g)
    ab = mn.cosine_alpha_bars(Tt)
    model_path = os.path.join(out_dir, f"{name}.safetensors")
    mn.write_model(model_path, net, mean, std, ab, skeleton,
                   {"provenance": {"data": "none: seeded random parameters (training/export_fixture.py)",
                                   "command": "python3 training/export_fixture.py"}})
    # Random entries observed; the online case: every frame but the newest observed, trackers in the newest.
    masks = [(torch.rand(Wt, D, generator=g) < 0.4).float(), torch.zeros(Wt, D)]
    masks[1][:-1, :] = 1.0
    masks[1][-1, 36:45] = 1.0
    masks[1][-1, 72:81] = 1.0
    tensors: dict[str, torch.Tensor] = {}
    cases: dict[str, list] = {"forward": [], "ddim": []}
    with torch.no_grad():
        for i, (t, m) in enumerate(zip([0, 7], masks)):
            obs = torch.randn(Wt, D, generator=g) * 1.5
            x = m * obs + (1 - m) * torch.randn(Wt, D, generator=g)
            out = net(x[None], m[None], torch.tensor([t]))[0]
            tensors.update({f"forward.{i}.x": x, f"forward.{i}.m": m, f"forward.{i}.out": out})
            cases["forward"].append({"t": t})
        K, s, m = 3, 1.0, masks[1]
        obs = torch.randn(Wt, D, generator=g)
        noise = torch.randn(Wt, D, generator=g)
        out = mn.ddim_sample(net, obs[None], m[None], ab, K, None, guidance=s, noise=noise[None])[0]
        tensors.update({"ddim.0.obs": obs, "ddim.0.mask": m, "ddim.0.noise": noise, "ddim.0.out": out})
        cases["ddim"].append({"K": K, "guidance": s, "eta": 0.0, "timesteps": mn.ddim_timesteps(Tt, K)})
    io_path = os.path.join(out_dir, f"{name}_io.safetensors")
    mn.write_tensor_file(io_path, tensors, {"cases": json.dumps(cases), "model": f"{name}.safetensors",
                                            "written_by": "training/export_fixture.py"})
    return model_path, io_path


if __name__ == "__main__":
    main()
