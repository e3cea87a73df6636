#!/usr/bin/env python3
"""The bodyd diffusion networks ("mlpwin-v1", "tcn-v1"), their noise schedule, DDIM sampler and model-file writer.

The C++ runtime (model/src/mlpwin.cpp, tcn.cpp, sampler.cpp, model_file.cpp) implements exactly the
same networks and sampler; tests/model checks the two against fixtures written by
training/export_fixture.py. The model file layout is specified in docs/model-file.md.

Method: CondMDI-style masked conditional diffusion (Cohan et al., "Flexible Motion In-betweening
with Diffusion Models", Sec. 4 and Algorithm 2): a window of W frames x D features, x0 prediction,
the observed entries replace the noisy sample under the mask and the mask is an input.

Only this module's public API is used by train.py:
  MlpWin(W, D, E=64, H=512, L=2, TE=64, T=100); forward(x, m, t) with x, m (B, W, D), t (B,) long
  TcnCausal(W, D, C=128, K=3, L=5, R=5, TE=64, T=100); the same forward
  ARCHITECTURES: architecture name -> class (each class has ARCHITECTURE and config())
  cosine_alpha_bars(T)
  ddim_timesteps(T, K)
  ddim_sample(net, obs, mask, alpha_bars, K, generator, guidance=1.0, eta=0.0, noise=None)
  write_model(path, net, mean, std, alpha_bars, skeleton, metadata)

Command line (a random-initialised model for benchmarks, no training):
  python3 training/model_net.py --random-model OUT.safetensors --W 20 --E 64 --H 512 --L 2
  python3 training/model_net.py --random-model OUT.safetensors --arch tcn-v1 --W 64 --C 128 --K 3 --L 5 --R 5
Adding the checksum to a model file written before it (docs/model-file.md, "Checksum"):
  python3 training/model_net.py --restamp FILE...
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import struct
from typing import Any, Mapping

import torch
from torch import nn
import torch.nn.functional as F

ARCHITECTURE = "mlpwin-v1"  # the default network; each class names its own (ARCHITECTURE)
FORMAT = "bodyd-model"
FORMAT_VERSION = "1"
# Checksum metadata keys (docs/model-file.md, "Checksum"); the C++ loader requires them in a model.
CHECKSUM_KEY = "checksum"
TENSOR_CHECKSUMS_KEY = "tensor_checksums"
# Mirror of bodyd::features::kVersion (model/include/bodyd/inference/features.h); the C++ loader
# rejects a model whose feature_version differs. Pass metadata["feature_version"] to override.
FEATURE_VERSION = 1
SKELETON_JOINTS = 22
LAYERNORM_EPS = 1e-5
# Cosine schedule (Nichol & Dhariwal 2021, Eq. 17) offset s, and the clip range of alpha_bar.
COSINE_S = 0.008
ALPHA_BAR_MIN = 1e-5
ALPHA_BAR_MAX = 0.9999


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal embedding of integer steps t (B,) -> (B, dim), float32.

    half = dim / 2, freq_i = exp(-ln(10000) * i / half) for i in [0, half),
    emb = concat(sin(t * freq), cos(t * freq)). Computed in float64 and rounded to float32, so that
    the C++ table (also float64 -> float32) matches to the last bit or so.
    """
    half = dim // 2
    i = torch.arange(half, dtype=torch.float64, device=t.device)
    freq = torch.exp(-math.log(10000.0) * i / half)
    args = t.to(torch.float64)[:, None] * freq[None, :]
    return torch.cat([torch.sin(args), torch.cos(args)], dim=1).to(torch.float32)


class ResBlock(nn.Module):
    def __init__(self, H: int):
        super().__init__()
        self.norm = nn.LayerNorm(H, eps=LAYERNORM_EPS)
        self.fc1 = nn.Linear(H, H)
        self.fc2 = nn.Linear(H, H)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        return h + self.fc2(F.silu(self.fc1(self.norm(h))))


def add_mlp_trunk(net: nn.Module, frames: int, D: int, E: int, H: int, L: int, TE: int) -> None:
    """mlpwin-v1's modules over `frames` frames, registered on `net` in this order (the order of
    net.parameters(), which a checkpoint's optimizer state follows): enc, inp, time1, time2,
    blocks, out_norm, out, dec1, dec2. tcnmlp-v1's trunk is the same over its newest N frames."""
    net.enc = nn.Linear(2 * D, E)
    net.inp = nn.Linear(frames * E, H)
    net.time1 = nn.Linear(TE, H)
    net.time2 = nn.Linear(H, H)
    net.blocks = nn.ModuleList([ResBlock(H) for _ in range(L)])
    net.out_norm = nn.LayerNorm(H, eps=LAYERNORM_EPS)
    net.out = nn.Linear(H, frames * E)
    net.dec1 = nn.Linear(2 * E, E)
    net.dec2 = nn.Linear(E, D)


class MlpWin(nn.Module):
    """mlpwin-v1: per-frame encoder, MLP trunk over the whole window, per-frame decoder.

    forward(x, m, t): x (B, W, D) noisy sample with observed entries already replaced by the
    observations, m (B, W, D) mask (1 = observed), t (B,) long in [0, T). Returns x0_hat (B, W, D).
    State-dict names (stable, they are the model file's tensor names): enc.*, inp.*, time1.*,
    time2.*, blocks.<b>.norm.*, blocks.<b>.fc1.*, blocks.<b>.fc2.*, out_norm.*, out.*, dec1.*, dec2.*
    """

    ARCHITECTURE = "mlpwin-v1"

    def __init__(self, W: int, D: int, E: int = 64, H: int = 512, L: int = 2, TE: int = 64, T: int = 100):
        super().__init__()
        if TE % 2 != 0:
            raise ValueError(f"TE must be even, got {TE}")
        self.W, self.D, self.E, self.H, self.L, self.TE, self.T = W, D, E, H, L, TE, T
        add_mlp_trunk(self, W, D, E, H, L, TE)

    def config(self) -> dict:
        return {"W": self.W, "D": self.D, "E": self.E, "H": self.H, "L": self.L, "TE": self.TE, "T": self.T}

    def forward(self, x: torch.Tensor, m: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        B = x.shape[0]
        e = F.silu(self.enc(torch.cat([x, m], dim=-1)))                      # (B, W, E)
        h = self.inp(e.reshape(B, self.W * self.E))                           # (B, H)
        h = h + self.time2(F.silu(self.time1(timestep_embedding(t, self.TE))))
        for blk in self.blocks:
            h = blk(h)
        z = self.out(F.silu(self.out_norm(h))).reshape(B, self.W, self.E)    # frame-major
        return self.dec2(F.silu(self.dec1(torch.cat([z, e], dim=-1))))      # (B, W, D)


class CausalBlock(nn.Module):
    """One residual block of tcn-v1: h + fc(SiLU(causal_conv(LayerNorm(h)))), per frame LayerNorm over
    channels, a dilated 1-D convolution over frames that sees only the current and earlier frames
    (zeros before the window's first frame)."""

    def __init__(self, C: int, K: int, dilation: int):
        super().__init__()
        self.norm = nn.LayerNorm(C, eps=LAYERNORM_EPS)
        self.conv = nn.Conv1d(C, C, K, dilation=dilation)
        self.fc = nn.Linear(C, C)
        self.pad = (K - 1) * dilation

    def forward(self, h: torch.Tensor) -> torch.Tensor:                    # (B, W, C)
        n = self.norm(h).transpose(1, 2)                                   # (B, C, W)
        a = F.silu(self.conv(F.pad(n, (self.pad, 0))))                     # causal: left padding only
        return h + self.fc(a.transpose(1, 2))


class TcnCausal(nn.Module):
    """tcn-v1: a temporal convolutional denoiser whose weights are shared over time.

    forward(x, m, t) as MlpWin's: x (B, W, D) noisy sample with observed entries replaced by the
    observations, m (B, W, D) the mask, t (B,) long. Per frame e_w = SiLU(enc([x_w; m_w])) + temb(t);
    L causal residual blocks, block b with kernel K and dilation 2^(b mod R); per frame
    y_w = dec2(SiLU(dec1(SiLU(out_norm(h_w))))). Frame w's output depends on frames w-F+1..w only,
    F = 1 + (K-1) * sum_b 2^(b mod R) (receptive_field()), so a window longer than F gives the newest
    frame the output of an unbounded stream and the C++ runtime can stream it (docs/model-file.md).
    State-dict names: enc.*, time1.*, time2.*, blocks.<b>.norm.*, blocks.<b>.conv.* (weight
    [C, C, K]), blocks.<b>.fc.*, out_norm.*, dec1.*, dec2.*
    """

    ARCHITECTURE = "tcn-v1"

    def __init__(self, W: int, D: int, C: int = 128, K: int = 3, L: int = 5, R: int = 5, TE: int = 64,
                 T: int = 100):
        super().__init__()
        if TE % 2 != 0:
            raise ValueError(f"TE must be even, got {TE}")
        if not 1 <= R <= 16:
            raise ValueError(f"R must be in [1, 16], got {R}")
        self.W, self.D, self.C, self.K, self.L, self.R, self.TE, self.T = W, D, C, K, L, R, TE, T
        self.enc = nn.Linear(2 * D, C)
        self.time1 = nn.Linear(TE, C)
        self.time2 = nn.Linear(C, C)
        self.blocks = nn.ModuleList([CausalBlock(C, K, 2 ** (b % R)) for b in range(L)])
        self.out_norm = nn.LayerNorm(C, eps=LAYERNORM_EPS)
        self.dec1 = nn.Linear(C, C)
        self.dec2 = nn.Linear(C, D)

    def config(self) -> dict:
        return {"W": self.W, "D": self.D, "C": self.C, "K": self.K, "L": self.L, "R": self.R, "TE": self.TE,
                "T": self.T}

    def receptive_field(self) -> int:
        return 1 + (self.K - 1) * sum(2 ** (b % self.R) for b in range(self.L))

    def forward(self, x: torch.Tensor, m: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        temb = self.time2(F.silu(self.time1(timestep_embedding(t, self.TE))))   # (B, C)
        h = F.silu(self.enc(torch.cat([x, m], dim=-1))) + temb[:, None, :]     # (B, W, C)
        for blk in self.blocks:
            h = blk(h)
        return self.dec2(F.silu(self.dec1(F.silu(self.out_norm(h)))))         # (B, W, D)


class TcnMlp(nn.Module):
    """tcnmlp-v1: mlpwin-v1 over the newest N frames, given a causal TCN's summary of the whole window.

    forward(x, m, t) as MlpWin's, on a W-frame window (W >= N). The context network sees only the
    observations: per frame c_w = SiLU(cenc([m_w * x_w; m_w])), then B causal residual blocks
    (CausalBlock, kernel K, dilation 2^(b mod R)) and SiLU(cnorm(.)). It does not see the step t nor
    the noise, so it is the same at every diffusion step of a frame; its output at the newest frame,
    which depends on frames W-F..W-1 (F = receptive_field()), enters the trunk as ctx(c_newest).
    The newest N frames are mlpwin-v1's: e_w = SiLU(enc([x_w; m_w])), h = inp(e flattened) +
    ctx(c_newest) + time embedding, L residual blocks, out and the per-frame decoder dec1/dec2 of
    [z_w; e_w]. The W-N older frames are decoded from the context alone: cdec2(SiLU(cdec1(c_w))).
    State-dict names: cenc.*, cblocks.<b>.{norm,conv,fc}.*, cnorm.*, cdec1.*, cdec2.*, ctx.*, and
    mlpwin-v1's enc.*, inp.*, time1.*, time2.*, blocks.<b>.{norm,fc1,fc2}.*, out_norm.*, out.*,
    dec1.*, dec2.*
    """

    ARCHITECTURE = "tcnmlp-v1"

    def __init__(self, W: int, D: int, N: int = 20, E: int = 64, H: int = 512, L: int = 2, C: int = 64,
                 K: int = 3, B: int = 5, R: int = 5, TE: int = 64, T: int = 100):
        super().__init__()
        if TE % 2 != 0:
            raise ValueError(f"TE must be even, got {TE}")
        if not 1 <= N <= W:
            raise ValueError(f"N must be in [1, W={W}], got {N}")
        if not 1 <= R <= 16:
            raise ValueError(f"R must be in [1, 16], got {R}")
        self.W, self.D, self.N, self.E, self.H, self.L = W, D, N, E, H, L
        self.C, self.K, self.B, self.R, self.TE, self.T = C, K, B, R, TE, T
        self.cenc = nn.Linear(2 * D, C)
        self.cblocks = nn.ModuleList([CausalBlock(C, K, 2 ** (b % R)) for b in range(B)])
        self.cnorm = nn.LayerNorm(C, eps=LAYERNORM_EPS)
        self.cdec1 = nn.Linear(C, C)
        self.cdec2 = nn.Linear(C, D)
        self.ctx = nn.Linear(C, H)
        add_mlp_trunk(self, N, D, E, H, L, TE)

    def config(self) -> dict:
        return {"W": self.W, "D": self.D, "N": self.N, "E": self.E, "H": self.H, "L": self.L, "C": self.C,
                "K": self.K, "B": self.B, "R": self.R, "TE": self.TE, "T": self.T}

    def receptive_field(self) -> int:
        return 1 + (self.K - 1) * sum(2 ** (b % self.R) for b in range(self.B))

    def context(self, x: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
        c = F.silu(self.cenc(torch.cat([x * m, m], dim=-1)))                   # (B, W, C)
        for blk in self.cblocks:
            c = blk(c)
        return F.silu(self.cnorm(c))

    def forward(self, x: torch.Tensor, m: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        Bn, W, N = x.shape[0], self.W, self.N
        c = self.context(x, m)
        e = F.silu(self.enc(torch.cat([x[:, W - N:], m[:, W - N:]], dim=-1)))   # (B, N, E)
        h = self.inp(e.reshape(Bn, N * self.E)) + self.ctx(c[:, W - 1])
        h = h + self.time2(F.silu(self.time1(timestep_embedding(t, self.TE))))
        for blk in self.blocks:
            h = blk(h)
        z = self.out(F.silu(self.out_norm(h))).reshape(Bn, N, self.E)
        newest = self.dec2(F.silu(self.dec1(torch.cat([z, e], dim=-1))))       # (B, N, D)
        if N == W:
            return newest
        older = self.cdec2(F.silu(self.cdec1(c[:, :W - N])))                     # (B, W-N, D)
        return torch.cat([older, newest], dim=1)


ARCHITECTURES = {MlpWin.ARCHITECTURE: MlpWin, TcnCausal.ARCHITECTURE: TcnCausal, TcnMlp.ARCHITECTURE: TcnMlp}


def cosine_alpha_bars(T: int) -> torch.Tensor:
    """alpha_bar[t] for t = 0..T-1 (float32), the cosine schedule of Nichol & Dhariwal (2021).

    f(u) = cos(((u + s) / (1 + s)) * pi / 2)^2 with s = 0.008;
    alpha_bar[t] = clip(f((t + 1) / T) / f(0), 1e-5, 0.9999), computed in float64.
    Step t = 0 is the least noisy, t = T-1 the noisiest (alpha_bar ~ 0, clipped to 1e-5).
    (Clipping alpha_bar directly replaces the paper's clipping of beta to 0.999.)
    """
    u = (torch.arange(T, dtype=torch.float64) + 1.0) / T
    f = torch.cos((u + COSINE_S) / (1.0 + COSINE_S) * math.pi / 2) ** 2
    f0 = math.cos(COSINE_S / (1.0 + COSINE_S) * math.pi / 2) ** 2
    return (f / f0).clamp(ALPHA_BAR_MIN, ALPHA_BAR_MAX).to(torch.float32)


def ddim_timesteps(T: int, K: int) -> list[int]:
    """The K DDIM steps, from T-1 down to 0: tau_k = floor((T-1) * (K-1-k) / (K-1)), k = 0..K-1.

    K = 1 gives [T-1]. Requires 1 <= K <= T (then the steps are distinct). T=100, K=4: [99, 66, 33, 0].
    """
    if not 1 <= K <= T:
        raise ValueError(f"K must be in [1, T={T}], got {K}")
    if K == 1:
        return [T - 1]
    return [((T - 1) * (K - 1 - k)) // (K - 1) for k in range(K)]


@torch.no_grad()
def ddim_sample(net: nn.Module, obs: torch.Tensor, mask: torch.Tensor, alpha_bars: torch.Tensor, K: int,
                generator: torch.Generator | None, guidance: float = 1.0, eta: float = 0.0,
                noise: torch.Tensor | None = None) -> torch.Tensor:
    """DDIM imputation sampling (CondMDI Algorithm 2 with DDIM steps), in normalised feature space.

    obs, mask: (B, W, D) (mask 0/1). alpha_bars: (T,). K steps at ddim_timesteps(T, K).
    noise: the initial x_{T-1} (B, W, D); drawn from `generator` when None.
    At step tau with ab = alpha_bar[tau]:
      inp   = mask * obs + (1 - mask) * x                     (x := inp, Alg. 2 line 4)
      x0    = net(inp, mask, tau); with guidance s != 1:
              x0 = x0_u + s * (x0_c - x0_u), x0_u = net(x, 0, tau) (obs and mask all zero)
      x0    = mask * obs + (1 - mask) * x0
      last step: return x0. Otherwise, with ab' = alpha_bar[next tau]:
      eps   = (x - sqrt(ab) * x0) / sqrt(1 - ab)
      sigma = eta * sqrt((1 - ab') / (1 - ab)) * sqrt(1 - ab / ab')
      x     = sqrt(ab') * x0 + sqrt(1 - ab' - sigma^2) * eps + sigma * z,  z ~ N(0, I) from generator
    """
    T = alpha_bars.shape[0]
    taus = ddim_timesteps(T, K)
    device = obs.device
    mask = mask.to(obs.dtype)
    # Noise is drawn on the generator's device (CPU or CUDA generators both work), then moved.
    gen_device = generator.device if generator is not None else device

    if noise is None:
        x = torch.randn(obs.shape, generator=generator, dtype=obs.dtype, device=gen_device).to(device)
    else:
        x = noise.to(device=device, dtype=obs.dtype).clone()
    B = obs.shape[0]
    x0 = x
    for k, tau in enumerate(taus):
        x = mask * obs + (1.0 - mask) * x
        t = torch.full((B,), tau, dtype=torch.long, device=device)
        if guidance == 1.0:
            x0 = net(x, mask, t)
        else:
            both = net(torch.cat([x, x]), torch.cat([mask, torch.zeros_like(mask)]), torch.cat([t, t]))
            x0_c, x0_u = both[:B], both[B:]
            x0 = x0_u + guidance * (x0_c - x0_u)
        x0 = mask * obs + (1.0 - mask) * x0
        if k == K - 1:
            break
        ab = float(alpha_bars[tau])
        ab_next = float(alpha_bars[taus[k + 1]])
        eps = (x - math.sqrt(ab) * x0) / math.sqrt(1.0 - ab)
        sigma = eta * math.sqrt((1.0 - ab_next) / (1.0 - ab)) * math.sqrt(max(0.0, 1.0 - ab / ab_next))
        x = math.sqrt(ab_next) * x0 + math.sqrt(max(0.0, 1.0 - ab_next - sigma * sigma)) * eps
        if sigma > 0.0:
            z = torch.randn(obs.shape, generator=generator, dtype=obs.dtype, device=gen_device).to(device)
            x = x + sigma * z
    return x0


# ---- model file (docs/model-file.md): the safetensors container layout, written by hand ----

def _tensor_bytes(t: torch.Tensor) -> bytes:
    a = t.detach().to("cpu", torch.float32).contiguous().numpy()
    return a.astype("<f4", copy=False).tobytes()


def write_tensor_file(path: str, tensors: Mapping[str, torch.Tensor], metadata: Mapping[str, str]) -> None:
    """Writes tensors (all as F32) and string metadata in the safetensors layout.

    8-byte little-endian header length N, N bytes of JSON header (padded with spaces to a multiple of
    8 so the data starts aligned), then the tensors' raw little-endian bytes, back to back in the
    order given.
    """
    _write_container(path, [(name, [int(s) for s in t.shape], _tensor_bytes(t)) for name, t in tensors.items()], metadata)


def _write_container(path: str, blobs: list[tuple[str, list[int], bytes]], metadata: Mapping[str, str]) -> None:
    """The writer behind write_tensor_file: (name, shape, raw F32 bytes) in file order.

    Adds the checksum (docs/model-file.md, "Checksum"): metadata "tensor_checksums" (JSON object,
    tensor name -> "sha256:" + hex of its bytes) and "checksum" ("sha256:" + hex of the 8-byte
    length, the header with the checksum's 64 digits written as '0', and the data).
    """
    meta = {str(k): str(v) for k, v in metadata.items() if k not in (CHECKSUM_KEY, TENSOR_CHECKSUMS_KEY)}
    meta[TENSOR_CHECKSUMS_KEY] = json.dumps({name: "sha256:" + hashlib.sha256(b).hexdigest() for name, _, b in blobs},
                                            separators=(",", ":"))
    placeholder = "sha256:" + "0" * 64
    meta[CHECKSUM_KEY] = placeholder
    header: dict[str, Any] = {"__metadata__": meta}
    offset = 0
    for name, shape, b in blobs:
        header[name] = {"dtype": "F32", "shape": shape, "data_offsets": [offset, offset + len(b)]}
        offset += len(b)
    hjson = json.dumps(header, separators=(",", ":")).encode("utf-8")
    hjson += b" " * ((-len(hjson)) % 8)
    length = struct.pack("<Q", len(hjson))
    digest = hashlib.sha256(length + hjson)
    for _, _, b in blobs:
        digest.update(b)
    quoted = f'"{placeholder}"'.encode()
    assert hjson.count(quoted) == 1
    hjson = hjson.replace(quoted, f'"sha256:{digest.hexdigest()}"'.encode())
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(length)
        f.write(hjson)
        for _, _, b in blobs:
            f.write(b)
    os.replace(tmp, path)


def restamp(path: str) -> None:
    """Rewrites a container written before checksums with the checksum; tensors and metadata are
    kept byte for byte (the header is re-serialised compactly, in the same order)."""
    blobs, meta = _read_container(path)
    _write_container(path, blobs, meta)


def read_tensor_file(path: str) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """Reads a file written by write_tensor_file (F32 only). For tests and tools."""
    import numpy as np
    blobs, meta = _read_container(path)
    out = {}
    for name, shape, b in blobs:
        out[name] = torch.from_numpy(np.frombuffer(b, dtype="<f4").reshape(shape).copy())
    return out, meta


def _read_container(path: str) -> tuple[list[tuple[str, list[int], bytes]], dict[str, str]]:
    """The tensors of a container as (name, shape, raw little-endian F32 bytes) in file order, and
    its metadata (F32 only)."""
    with open(path, "rb") as f:
        raw = f.read()
    (n,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8:8 + n].decode("utf-8"))
    meta = header.pop("__metadata__", {})
    data = raw[8 + n:]
    blobs = []
    for name, info in header.items():
        if info["dtype"] != "F32":
            raise ValueError(f"{path}: tensor {name}: dtype {info['dtype']} not supported")
        b, e = info["data_offsets"]
        blobs.append((name, list(info["shape"]), data[b:e]))
    return blobs, meta


def _skeleton_json(skeleton: Any) -> str:
    """skeleton: dict {"names", "parents", "offsets_m"} or its JSON string; checked here too."""
    sk = json.loads(skeleton) if isinstance(skeleton, str) else dict(skeleton)
    names, parents, offsets = list(sk["names"]), [int(p) for p in sk["parents"]], sk["offsets_m"]
    if not (len(names) == len(parents) == len(offsets) == SKELETON_JOINTS):
        raise ValueError(f"skeleton must have {SKELETON_JOINTS} joints (names, parents, offsets_m)")
    for i, p in enumerate(parents):
        if (i == 0 and p != -1) or (i > 0 and not 0 <= p < i):
            raise ValueError(f"skeleton joint {i} ({names[i]}): parent {p} invalid")
    offs = [[float(v) for v in o] for o in offsets]
    if any(len(o) != 3 for o in offs):
        raise ValueError("skeleton offsets_m must be [x, y, z] per joint")
    return json.dumps({"names": names, "parents": parents, "offsets_m": offs}, separators=(",", ":"))


def write_model(path: str, net: nn.Module, mean: torch.Tensor, std: torch.Tensor, alpha_bars: torch.Tensor,
                skeleton: Any, metadata: dict) -> None:
    """Writes a bodyd model file (docs/model-file.md).

    mean, std: (D,) feature normalisation (the network sees (f - mean) / std).
    alpha_bars: (T,), e.g. cosine_alpha_bars(net.T).
    skeleton: {"names": [22 str], "parents": [22 int], "offsets_m": [[x, y, z] * 22]} (metres) or its JSON.
    metadata: "provenance" (dict or str, free form: data, split, steps, wall time, hardware, commit,
      command) and optionally "feature_version" (default FEATURE_VERSION), "fps" (default "30"); any
      other key is stored too (non-str values as JSON). The format keys are set here and cannot be overridden.
    """
    cfg = net.config()
    D, T = cfg["D"], cfg["T"]
    mean = torch.as_tensor(mean, dtype=torch.float32).reshape(-1)
    std = torch.as_tensor(std, dtype=torch.float32).reshape(-1)
    alpha_bars = torch.as_tensor(alpha_bars, dtype=torch.float32).reshape(-1)
    if mean.numel() != D or std.numel() != D:
        raise ValueError(f"mean/std must have D={D} entries, got {mean.numel()}/{std.numel()}")
    if not bool((std > 0).all()) or not bool(torch.isfinite(std).all()) or not bool(torch.isfinite(mean).all()):
        raise ValueError("norm std must be finite and > 0, mean finite")
    if alpha_bars.numel() != T:
        raise ValueError(f"alpha_bars must have T={T} entries, got {alpha_bars.numel()}")

    meta: dict[str, str] = {}
    for k, v in metadata.items():
        meta[str(k)] = v if isinstance(v, str) else json.dumps(v, sort_keys=True)
    meta.setdefault("feature_version", str(FEATURE_VERSION))
    meta.setdefault("fps", "30")
    meta.setdefault("provenance", "{}")
    meta.update({
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "architecture": net.ARCHITECTURE,
        "config": json.dumps(cfg, separators=(",", ":")),
        "skeleton": _skeleton_json(skeleton),
    })
    tensors: dict[str, torch.Tensor] = {k: v for k, v in net.state_dict().items()}
    tensors["norm.mean"] = mean
    tensors["norm.std"] = std
    tensors["diffusion.alpha_bar"] = alpha_bars
    write_tensor_file(path, tensors, meta)


def load_model(path: str, device: str = "cpu") -> tuple[nn.Module, dict[str, torch.Tensor], dict[str, str]]:
    """Reads a model file back: (net in eval mode, {"norm.mean", "norm.std", "diffusion.alpha_bar"}, metadata)."""
    tensors, meta = read_tensor_file(path)
    if meta.get("format") != FORMAT or meta.get("architecture") not in ARCHITECTURES:
        raise ValueError(f"{path}: not a {FORMAT} file of a known architecture ({', '.join(ARCHITECTURES)})")
    cfg = json.loads(meta["config"])
    net = ARCHITECTURES[meta["architecture"]](**cfg)
    extra = {k: tensors.pop(k) for k in ("norm.mean", "norm.std", "diffusion.alpha_bar")}
    net.load_state_dict(tensors, strict=True)
    return net.to(device).eval(), extra, meta


def skeleton_from_bvh(path: str, unit_to_m: float = 0.01) -> dict:
    """The joint hierarchy of a BVH file as {"names", "parents", "offsets_m"} (End Sites skipped)."""
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    stack: list[int] = []
    pending: int | None = None
    in_end = 0
    with open(path) as f:
        for line in f:
            tok = line.split()
            if not tok:
                continue
            if tok[0] == "MOTION":
                break
            if tok[0] in ("ROOT", "JOINT"):
                names.append(tok[1])
                parents.append(stack[-1] if stack else -1)
                offsets.append([0.0, 0.0, 0.0])
                pending = len(names) - 1
            elif tok[0] == "End":
                pending = -1
            elif tok[0] == "{":
                if pending == -1:
                    in_end += 1
                elif pending is not None:
                    stack.append(pending)
                pending = None
            elif tok[0] == "}":
                if in_end:
                    in_end -= 1
                else:
                    stack.pop()
            elif tok[0] == "OFFSET" and not in_end and stack:
                offsets[stack[-1]] = [float(v) * unit_to_m for v in tok[1:4]]
    return {"names": names, "parents": parents, "offsets_m": offsets}


def _repo_root() -> str:
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _git_commit() -> str:
    try:
        import subprocess
        return subprocess.run(["git", "-C", _repo_root(), "rev-parse", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
    except Exception:
        return "unknown"


def add_architecture_args(p: argparse.ArgumentParser, L_default: int = 0) -> None:
    """--arch and the network's sizes (train.py's and --random-model's); make_net() builds from them."""
    p.add_argument("--arch", choices=sorted(ARCHITECTURES), default=MlpWin.ARCHITECTURE,
                   help="the network (docs/model-file.md, \"Architectures\"); train.py's --init-from takes the model's")
    p.add_argument("--E", type=int, default=64, help="mlpwin-v1, tcnmlp-v1: per-frame embedding")
    p.add_argument("--H", type=int, default=512, help="mlpwin-v1, tcnmlp-v1: trunk width")
    p.add_argument("--L", type=int, default=L_default,
                   help="residual blocks (0 = the architecture's default: mlpwin-v1 and tcnmlp-v1's trunk 2, tcn-v1 5)")
    p.add_argument("--C", type=int, default=0, help="tcn-v1, tcnmlp-v1: channels (0 = default: 128, 64)")
    p.add_argument("--N", type=int, default=20, help="tcnmlp-v1: newest frames the MLP trunk sees")
    p.add_argument("--B", type=int, default=5, help="tcnmlp-v1: causal blocks of the context network")
    p.add_argument("--K", type=int, default=3, help="tcn-v1, tcnmlp-v1: convolution kernel size in frames")
    p.add_argument("--R", type=int, default=5, help="tcn-v1, tcnmlp-v1: dilation cycle (block b has dilation 2^(b mod R))")
    p.add_argument("--TE", type=int, default=64, help="width of the diffusion step's sinusoid")
    p.add_argument("--T", type=int, default=100, help="diffusion steps")


def make_net(a: argparse.Namespace, W: int, D: int) -> nn.Module:
    """The network of add_architecture_args()'s arguments over W frames of D features."""
    if a.arch == TcnCausal.ARCHITECTURE:
        return TcnCausal(W, D, C=a.C or 128, K=a.K, L=a.L or 5, R=a.R, TE=a.TE, T=a.T)
    if a.arch == TcnMlp.ARCHITECTURE:
        return TcnMlp(W, D, N=a.N, E=a.E, H=a.H, L=a.L or 2, C=a.C or 64, K=a.K, B=a.B, R=a.R, TE=a.TE, T=a.T)
    return MlpWin(W, D, E=a.E, H=a.H, L=a.L or 2, TE=a.TE, T=a.T)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--random-model", metavar="OUT",
                    help="write a random-initialised model (identity normalisation) for benchmarks")
    ap.add_argument("--restamp", metavar="FILE", nargs="+",
                    help="add the checksum to model files written before it (tensors and metadata unchanged)")
    ap.add_argument("--W", type=int, default=20)
    ap.add_argument("--D", type=int, default=191)
    add_architecture_args(ap, L_default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skeleton-bvh", default=os.path.join(_repo_root(), "tests", "data", "walk_60.bvh"))
    a = ap.parse_args()
    if a.restamp:
        for path in a.restamp:
            restamp(path)
            print(f"stamped {path}")
        return
    if not a.random_model:
        ap.error("give --random-model OUT or --restamp FILE...")
    torch.manual_seed(a.seed)
    net = make_net(a, a.W, a.D)
    skeleton = skeleton_from_bvh(a.skeleton_bvh)
    prov = {"data": "none (random initialisation)", "seed": a.seed, "git_commit": _git_commit(),
            "command": "python3 training/model_net.py " + " ".join(sys.argv[1:])}
    write_model(a.random_model, net, torch.zeros(a.D), torch.ones(a.D), cosine_alpha_bars(a.T), skeleton,
                {"provenance": prov})
    n = sum(p.numel() for p in net.parameters())
    print(f"wrote {a.random_model}: {net.ARCHITECTURE} {net.config()} ({n} parameters)")


if __name__ == "__main__":
    main()
