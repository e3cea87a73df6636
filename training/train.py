#!/usr/bin/env python3
"""Trains bodyd's reconstruction model: CondMDI-style masked conditional diffusion (x0 prediction).

Input: windows exported by `bodyd-dataset` (NAME.npy: N x W x D float32 features, NAME.json: metadata),
computed by the C++ feature code the runtime uses. Output: a model file (docs/model-file.md) that the C++
inference loads. Resumable: checkpoints in --run-dir; run the same command again to continue.

  /usr/bin/python3 training/train.py --data training/data/train --run-dir training/runs/default \
      --out models/bodyd-default.safetensors

Runs on CUDA when available (--device auto), else CPU.
"""
import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from model_net import MlpWin, cosine_alpha_bars, ddim_sample, write_model  # noqa: E402


def parse_args():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="dataset base path (without .npy/.json)")
    p.add_argument("--run-dir", required=True, help="checkpoints and logs")
    p.add_argument("--out", required=True, help="model file to write at the end")
    p.add_argument("--steps", type=int, default=60000)
    p.add_argument("--minutes", type=float, default=0, help="stop (and export) after this wall time, 0 = no limit")
    p.add_argument("--batch", type=int, default=256)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--weight-decay", type=float, default=1e-4)
    p.add_argument("--E", type=int, default=64)
    p.add_argument("--H", type=int, default=512)
    p.add_argument("--L", type=int, default=2)
    p.add_argument("--T", type=int, default=100)
    p.add_argument("--uncond-prob", type=float, default=0.1, help="fraction of samples with no condition (for guidance)")
    p.add_argument("--hand-drop-prob", type=float, default=0.15, help="per hand: probability of a tracking-loss span")
    p.add_argument("--full-prefix-prob", type=float, default=0.6,
                   help="probability that all frames but the newest are observed (the online case)")
    p.add_argument("--prefix-noise", type=float, default=0.05, help="noise (normalised units) on observed prefix frames")
    p.add_argument("--tracker-noise", type=float, default=0.01, help="noise (normalised units) on observed tracker entries")
    p.add_argument("--holdout-every", type=int, default=20, help="every Nth training clip is held out for monitoring")
    p.add_argument("--ema", type=float, default=0.999)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--threads", type=int, default=0, help="CPU threads for torch (0 = torch default)")
    p.add_argument("--device", default="auto")
    p.add_argument("--ckpt-every", type=int, default=1000)
    p.add_argument("--eval-every", type=int, default=1000)
    p.add_argument("--export-only", action="store_true",
                   help="write --out from the run's latest checkpoint (EMA weights) and exit, without training")
    return p.parse_args()


def git_commit():
    try:
        return subprocess.check_output(["git", "rev-parse", "--short", "HEAD"], cwd=os.path.dirname(__file__),
                                       stderr=subprocess.DEVNULL).decode().strip()
    except Exception:
        return "unknown"


class Masker:
    """Random observation masks (B, W, D): trackers always (with random hand-loss spans), a random-length
    prefix of fully observed frames (the frames the online loop has already emitted), some unconditioned."""

    def __init__(self, meta, W, D, args, device):
        self.W, self.D, self.args, self.device = W, D, args, device
        te = meta["tracker_entries"]
        self.head = torch.tensor(te["head"], device=device)
        self.hands = [torch.tensor(te["left_hand"], device=device), torch.tensor(te["right_hand"], device=device)]

    def __call__(self, B, gen):
        W, D, a, dev = self.W, self.D, self.args, self.device
        m = torch.zeros(B, W, D, device=dev)
        m[:, :, self.head] = 1.0
        frame_idx = torch.arange(W, device=dev).view(1, W)
        for hand in self.hands:
            vis = torch.ones(B, W, device=dev)
            drop = torch.rand(B, generator=gen, device=dev) < a.hand_drop_prob
            start = torch.randint(0, W, (B,), generator=gen, device=dev).view(B, 1)
            length = torch.randint(1, W + 1, (B,), generator=gen, device=dev).view(B, 1)
            span = (frame_idx >= start) & (frame_idx < start + length)
            vis[drop.view(B, 1) & span] = 0.0
            m[:, :, hand] = vis.unsqueeze(-1).expand(B, W, hand.numel())
        # Prefix of fully observed frames: length W-1 (online case) or uniform in [0, W-1].
        full = torch.rand(B, generator=gen, device=dev) < a.full_prefix_prob
        plen = torch.randint(0, W, (B,), generator=gen, device=dev)
        plen = torch.where(full, torch.full_like(plen, W - 1), plen)
        prefix = (frame_idx < plen.view(B, 1)).float()  # (B, W)
        m = torch.maximum(m, prefix.unsqueeze(-1).expand(B, W, D))
        uncond = torch.rand(B, generator=gen, device=dev) < a.uncond_prob
        m[uncond] = 0.0
        return m, prefix


def main():
    a = parse_args()
    torch.manual_seed(a.seed)
    np.random.seed(a.seed)
    if a.threads > 0:
        torch.set_num_threads(a.threads)
    dev = torch.device(("cuda" if torch.cuda.is_available() else "cpu") if a.device == "auto" else a.device)
    os.makedirs(a.run_dir, exist_ok=True)

    meta = json.load(open(a.data + ".json"))
    data = np.load(a.data + ".npy", mmap_mode="r")
    N, W, D = data.shape
    assert D == meta["dim"], "dataset dim disagrees with its metadata"
    # Hold out every Nth clip (by clip order) for monitoring; the validation split is never touched here.
    clip_of_window = np.repeat(np.arange(len(meta["clips"])), [c["windows"] for c in meta["clips"]])
    hold = (clip_of_window % a.holdout_every) == (a.holdout_every - 1)
    train_idx, hold_idx = np.nonzero(~hold)[0], np.nonzero(hold)[0]
    x_all = torch.from_numpy(np.ascontiguousarray(data))
    mean = x_all[torch.from_numpy(train_idx)].reshape(-1, D).mean(0)
    std = x_all[torch.from_numpy(train_idx)].reshape(-1, D).std(0).clamp_min(0.01)
    x_all = ((x_all - mean) / std).to(dev)
    train_idx_t = torch.from_numpy(train_idx).to(dev)
    hold_idx_t = torch.from_numpy(hold_idx).to(dev)
    print(f"data: {N} windows of {W}x{D} ({len(train_idx)} train, {len(hold_idx)} held out) on {dev}", flush=True)

    net = MlpWin(W, D, E=a.E, H=a.H, L=a.L, T=a.T).to(dev)
    ema = MlpWin(W, D, E=a.E, H=a.H, L=a.L, T=a.T).to(dev)
    ema.load_state_dict(net.state_dict())
    for p in ema.parameters():
        p.requires_grad_(False)
    opt = torch.optim.AdamW(net.parameters(), lr=a.lr, weight_decay=a.weight_decay)
    ab = cosine_alpha_bars(a.T).to(dev)
    masker = Masker(meta, W, D, a, dev)
    gen = torch.Generator(device=dev)
    gen.manual_seed(a.seed)
    nparams = sum(p.numel() for p in net.parameters())
    print(f"model: mlpwin-v1 W={W} D={D} E={a.E} H={a.H} L={a.L} T={a.T}, {nparams / 1e6:.2f} M parameters", flush=True)

    step, wall_before = 0, 0.0
    t0 = time.time()
    ckpt_path = os.path.join(a.run_dir, "ckpt.pt")
    if os.path.exists(ckpt_path):
        ck = torch.load(ckpt_path, map_location=dev)
        net.load_state_dict(ck["net"])
        ema.load_state_dict(ck["ema"])
        opt.load_state_dict(ck["opt"])
        gen.set_state(ck["gen"].cpu() if dev.type == "cpu" else ck["gen"])
        torch.set_rng_state(ck["torch_rng"])
        step, wall_before = ck["step"], ck.get("wall_s", 0.0)
        print(f"resumed from {ckpt_path} at step {step}", flush=True)

    def lr_at(s):
        # Linear warm-up, then cosine decay over the run; with --minutes the decay follows whichever of
        # steps and wall time runs out first, so a time-limited run still ends at a low learning rate.
        warm = 500
        if s < warm:
            return a.lr * (s + 1) / warm
        frac = (s - warm) / max(1, a.steps - warm)
        if a.minutes:
            frac = max(frac, (time.time() - t0 + wall_before) / 60.0 / a.minutes)
        return a.lr * 0.5 * (1 + math.cos(math.pi * min(1.0, frac)))

    def loss_on(model, idx, g):
        x0 = x_all[idx]
        B = x0.shape[0]
        m, prefix = masker(B, g)
        t = torch.randint(0, a.T, (B,), generator=g, device=dev)
        noise = torch.randn(x0.shape, generator=g, device=dev)
        abt = ab[t].view(B, 1, 1)
        xt = abt.sqrt() * x0 + (1 - abt).sqrt() * noise
        # Observations as the online loop gives them: emitted frames carry the model's own errors,
        # trackers their noise (both small, in normalised units).
        obs = x0 + a.prefix_noise * prefix.unsqueeze(-1) * torch.randn(x0.shape, generator=g, device=dev)
        obs = obs + a.tracker_noise * torch.randn(x0.shape, generator=g, device=dev)
        inp = m * obs + (1 - m) * xt
        pred = model(inp, m, t)
        w = 1.0 - 0.9 * m  # the unobserved part is what the model is for
        return ((pred - x0) ** 2 * w).sum() / w.sum()

    # Monitor: the online case (all frames but the newest observed, trackers in the newest), K-step DDIM,
    # error of the newest frame's joint positions in cm (all joints / lower body), on held-out clips.
    pos_entries = meta["joint_position_entries"]
    lower_names = ["Hips", "UpperLeg_L", "UpperLeg_R", "LowerLeg_L", "LowerLeg_R", "Foot_L", "Foot_R", "Toes_L", "Toes_R"]
    pos_idx = torch.tensor([pos_entries[n] for n in pos_entries], device=dev)            # (21, 3)
    lower_idx = torch.tensor([pos_entries[n] for n in lower_names], device=dev)
    mon_idx = hold_idx_t[torch.randperm(len(hold_idx_t), generator=torch.Generator().manual_seed(7))[:512].to(dev)] \
        if len(hold_idx_t) else None

    def monitor(model):
        x0 = x_all[mon_idx]
        B = x0.shape[0]
        m = torch.zeros_like(x0)
        m[:, :W - 1, :] = 1.0
        m[:, W - 1, masker.head] = 1.0
        for hand in masker.hands:
            m[:, W - 1, hand] = 1.0
        g = torch.Generator(device=dev)
        g.manual_seed(5)
        out = ddim_sample(model, x0, m, ab, 4, g)
        real_out = out[:, W - 1] * std.to(dev) + mean.to(dev)
        real_x0 = x0[:, W - 1] * std.to(dev) + mean.to(dev)
        def err(idx):
            return ((real_out[:, idx] - real_x0[:, idx]).norm(dim=-1)).mean().item() * 100
        return err(pos_idx), err(lower_idx)

    log = open(os.path.join(a.run_dir, "log.txt"), "a")
    last_print, seen = t0, 0
    hold_gen = torch.Generator(device=dev)
    while step < a.steps and not a.export_only:
        if a.minutes and (time.time() - t0 + wall_before) / 60.0 >= a.minutes:
            print(f"\nwall-time limit of {a.minutes} min reached at step {step}", flush=True)
            break
        for g_ in opt.param_groups:
            g_["lr"] = lr_at(step)
        idx = train_idx_t[torch.randint(0, len(train_idx_t), (a.batch,), generator=gen, device=dev)]
        net.train()
        loss = loss_on(net, idx, gen)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        with torch.no_grad():
            d = min(a.ema, (1 + step) / (10 + step))
            for pe, pn in zip(ema.parameters(), net.parameters()):
                pe.mul_(d).add_(pn.detach(), alpha=1 - d)
        step += 1
        seen += a.batch
        now = time.time()
        if now - last_print > 2 or step == a.steps:
            rate = seen / (now - last_print)
            elapsed = now - t0 + wall_before
            frac = step / a.steps
            bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
            eta = (a.steps - step) * a.batch / max(rate, 1e-9)
            sys.stdout.write(f"\r[{bar}] step {step}/{a.steps} loss {loss.item():.4f} lr {lr_at(step):.2e} "
                             f"{rate:.0f} samples/s elapsed {elapsed / 60:.1f} min eta {eta / 60:.1f} min   ")
            sys.stdout.flush()
            last_print, seen = now, 0
        if step % a.eval_every == 0 and len(hold_idx_t):
            ema.eval()
            hold_gen.manual_seed(1234)
            with torch.no_grad():
                hl = sum(loss_on(ema, hold_idx_t[i:i + 1024], hold_gen).item()
                         for i in range(0, min(len(hold_idx_t), 4096), 1024))
                hl /= len(range(0, min(len(hold_idx_t), 4096), 1024))
                all_cm, lower_cm = monitor(ema)
            msg = (f"step {step} train_loss {loss.item():.5f} holdout_loss_ema {hl:.5f} "
                   f"holdout_newest_frame_cm all {all_cm:.2f} lower {lower_cm:.2f} "
                   f"wall_min {(time.time() - t0 + wall_before) / 60:.1f}")
            print("\n" + msg, flush=True)
            log.write(msg + "\n")
            log.flush()
        if step % a.ckpt_every == 0 or step == a.steps:
            tmp = ckpt_path + ".tmp"
            torch.save({"net": net.state_dict(), "ema": ema.state_dict(), "opt": opt.state_dict(),
                        "gen": gen.get_state(), "torch_rng": torch.get_rng_state(), "step": step,
                        "wall_s": time.time() - t0 + wall_before, "args": vars(a)}, tmp)
            os.replace(tmp, ckpt_path)

    wall_s = time.time() - t0 + wall_before
    hw = torch.cuda.get_device_name(0) if dev.type == "cuda" else f"CPU ({platform.processor() or platform.machine()}, {torch.get_num_threads()} threads)"
    provenance = {
        "data": "Bandai Namco Research Motion Dataset (CC BY-NC 4.0), " + os.path.basename(a.data),
        "windows_total": int(N), "windows_train": int(len(train_idx)), "holdout_every_clip": a.holdout_every,
        "steps": step, "batch": a.batch, "wall_time_s": round(wall_s, 1), "hardware": hw,
        "git_commit": git_commit(), "command": " ".join(sys.argv), "args": vars(a),
        "torch": torch.__version__,
    }
    skeleton = meta["skeleton"]
    write_model(a.out, ema.cpu(), mean, std, ab.cpu(), skeleton,
                {"provenance": json.dumps(provenance), "fps": str(int(round(meta["fps"])))})
    print(f"\nwrote {a.out} after {step} steps, {wall_s / 60:.1f} min", flush=True)


if __name__ == "__main__":
    main()
