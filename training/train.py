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


def _limit_blas_threads(argv: list[str]) -> None:
    """--threads N also bounds the BLAS library's own thread pool. Debian's PyTorch calls OpenBLAS
    (libopenblas0-pthread), whose pool has one thread per core whatever torch.set_num_threads says:
    with --threads 1 a run still took both cores (perf: the second one in OpenBLAS's kernels and
    sched_yield) and slowed everything else on the machine. With more than one thread, torch's
    OpenMP threads spin between parallel regions while the BLAS threads spin too, and on two cores
    they starve each other; OMP_WAIT_POLICY=PASSIVE makes idle OpenMP threads sleep. Measured on
    the 2-core development machine (samples/s, docs/models.md, "Training threads"): mlpwin-v1 at
    batch 256, one core 1861, --threads 2 1965 (1018 with spinning OpenMP threads); tcn-v1 at
    batch 128, 225 and 296. The pool's size and the wait policy are read once, when the libraries
    load, so they are set here, before numpy (which loads the same OpenBLAS) and torch are
    imported. A value already in the environment wins (OPENBLAS_NUM_THREADS=2 with --threads 1
    ran mlpwin-v1 at 2519)."""
    n = None
    for i, arg in enumerate(argv):
        if arg == "--threads" and i + 1 < len(argv):
            n = argv[i + 1]
        elif arg.startswith("--threads="):
            n = arg.split("=", 1)[1]
    if n is not None and n.isdigit() and int(n) > 0:
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
            os.environ.setdefault(var, n)
        if int(n) > 1:
            os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def _keep_freed_memory() -> None:
    """glibc's malloc serves each block over its mmap threshold (at most 32 MB) with a fresh mmap and
    returns it to the kernel on free, and trims the heap's top likewise. A training step allocates and
    frees tensors of tens of MB (tcnmlp-v1 at batch 1024: 1024 x 64 x 191 floats are 50 MB), so every
    step faulted its memory back in page by page: 67,000 minor faults a second and a third of the CPU
    time in the kernel. Serving everything from the heap (M_MMAP_MAX 0) and never trimming it
    (M_TRIM_THRESHOLD) keeps freed memory for the next step: tcnmlp-v1 at batch 1024 went from 3.44 to
    1.47 s a step on the 2-core development machine (docs/models.md, "Training threads"). The
    arithmetic is unchanged. Other C libraries (no mallopt) are left as they are."""
    import ctypes
    import ctypes.util
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_mmap_max = -1, -4  # malloc.h
    mallopt(m_mmap_max, 0)
    mallopt(m_trim_threshold, ctypes.c_int(2**31 - 1))


_limit_blas_threads(sys.argv[1:])
_keep_freed_memory()
import numpy as np  # noqa: E402  (numpy loads OpenBLAS too)
import torch  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from model_net import MlpWin, TcnMlp, add_architecture_args, cosine_alpha_bars, ddim_sample, load_model, make_net, write_model  # noqa: E402


def add_mount_error_args(p, who, cm, deg, cm_help, deg_help):
    """--WHO-mount-cm and --WHO-mount-deg: a tracker's constant mounting error per sample, as a
    position offset (cm) and a rotation offset (degrees)."""
    p.add_argument(f"--{who}-mount-cm", type=float, default=cm, help=cm_help)
    p.add_argument(f"--{who}-mount-deg", type=float, default=deg, help=deg_help)


def parse_args():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
                                allow_abbrev=False)  # whole names: --threads is read before argparse runs
    p.add_argument("--data", required=True, help="dataset base path (without .npy/.json)")
    p.add_argument("--run-dir", required=True, help="checkpoints and logs")
    p.add_argument("--out", required=True, help="model file to write at the end")
    p.add_argument("--steps", type=int, default=60000)
    p.add_argument("--minutes", type=float, default=0, help="stop (and export) after this wall time, 0 = no limit")
    p.add_argument("--session-minutes", type=float, default=0,
                   help="this invocation's wall-time budget, 0 = no limit: when it runs out the trainer saves its "
                        "checkpoint and exits with status 3 without writing --out, and the same command given again "
                        "continues the run; unlike --minutes it leaves the learning-rate schedule alone, so a run "
                        "split over several sessions takes the same steps as one that ran through")
    p.add_argument("--batch", type=int, default=256)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--weight-decay", type=float, default=1e-4)
    p.add_argument("--warmup", type=int, default=500, help="linear learning-rate warm-up steps")
    add_architecture_args(p)
    p.add_argument("--uncond-prob", type=float, default=0.1, help="fraction of samples with no condition (for guidance)")
    p.add_argument("--hand-drop-prob", type=float, default=0.15, help="per hand: probability of a tracking-loss span")
    p.add_argument("--full-prefix-prob", type=float, default=0.6,
                   help="probability that all frames but the newest are observed (the online case)")
    p.add_argument("--prefix-noise", type=float, default=0.05, help="noise (normalised units) on observed prefix frames")
    p.add_argument("--self-prefix", type=float, default=0.0,
                   help="probability that a sample's observed prefix is the model's own reconstruction (EMA weights, "
                        "K-step DDIM from the trackers alone) instead of the truth: trains recovery from its own errors, "
                        "as the online loop feeds back what it emitted")
    p.add_argument("--self-prefix-steps", type=int, default=2, help="DDIM steps of the --self-prefix reconstruction")
    p.add_argument("--observed-weight", type=float, default=0.1,
                   help="loss weight of observed entries relative to unobserved ones (1 = equal)")
    p.add_argument("--tracker-noise", type=float, default=0.01, help="noise (normalised units) on observed tracker entries")
    p.add_argument("--extra-roles", default="",
                   help="body-tracker roles besides head and hands that a sample may observe (issue 44), comma-separated "
                        "from " + ",".join(EXTRA_ROLES) + " (empty: head and hands only, as before)")
    p.add_argument("--extra-role-prob", type=float, default=0.3,
                   help="per sample and extra role: probability that the role is tracked")
    p.add_argument("--extra-rot-only-prob", type=float, default=0.3,
                   help="of the tracked extra roles: probability that only the rotation is observed (an IMU tracker)")
    p.add_argument("--extra-none-prob", type=float, default=0.0,
                   help="per sample: probability that no extra role is observed at all (the user with a headset and "
                        "controllers only); otherwise each role is drawn with --extra-role-prob. 0 (default): the "
                        "per-role draws alone, which leave 0.7^8 = 6%% of the samples with head and hands only")
    p.add_argument("--extra-drop-prob", type=float, default=0.15,
                   help="per tracked extra role: probability of a tracking-loss span (as --hand-drop-prob)")
    add_mount_error_args(p, "extra", 2.0, 5.0,
                         "strapping error of an extra tracker: a constant position offset per sample, this many cm "
                         "(standard deviation per axis)",
                         "strapping error of an extra tracker: a constant rotation offset per sample, about this many "
                         "degrees (standard deviation per axis of the rotation vector)")
    p.add_argument("--xr-mount-prob", type=float, default=0.0,
                   help="per sample: probability that the headset and controllers are seen through a wrong mounting "
                        "(a user on the default mounting, issue 44: --device-frames xr costs 1.55x joint frames); "
                        "0 (default): never, as before")
    add_mount_error_args(p, "head", 1.5, 3.0,
                         "with --xr-mount-prob: the Head joint's constant position error, cm (standard deviation per "
                         "axis); bodyd-eval --device-frames xr measures the default mounting 2.2 cm off at the eyes, "
                         "5.3 degrees turned (about 1.2 cm at the joint)",
                         "with --xr-mount-prob: the Head joint's constant rotation error, degrees per axis")
    add_mount_error_args(p, "hand", 1.1, 8.0,
                         "with --xr-mount-prob: each wrist's constant position error, cm per axis (grip offset 1.2 cm, "
                         "14 degrees about a 6 cm lever)",
                         "with --xr-mount-prob: each wrist's constant rotation error, degrees per axis (grips 14 "
                         "degrees)")
    p.add_argument("--holdout-every", type=int, default=20, help="every Nth training clip is held out for monitoring")
    p.add_argument("--exclude-split", action="append", default=[], metavar="FILE",
                   help="never train on (nor monitor with) the clips this file lists: '#' comments, then one path per "
                        "line relative to the dataset root, as training/style-heldout.txt (repeatable)")
    p.add_argument("--ema", type=float, default=0.999)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--threads", type=int, default=0, help="CPU threads for torch and its BLAS library (0 = their defaults: one per core)")
    p.add_argument("--device", default="auto")
    p.add_argument("--ckpt-every", type=int, default=1000)
    p.add_argument("--eval-every", type=int, default=1000)
    p.add_argument("--init-from", default="",
                   help="start from this model file's weights and normalisation (fine-tuning); a run's checkpoint wins when resuming")
    p.add_argument("--init-trunk", default="", metavar="MODEL",
                   help="tcnmlp-v1: start its trunk (enc, inp, time, blocks, out, dec) and normalisation from an "
                        "mlpwin-v1 model with W = --N; the context's input to the trunk (ctx) starts at zero, so the "
                        "new model starts as that model")
    p.add_argument("--window", type=int, default=0,
                   help="model window W in frames (0 = the dataset's); a dataset with longer windows allows --time-warp")
    p.add_argument("--balance", type=float, default=0.0,
                   help="fraction of each batch drawn from dataset-1 clips (0 = uniform over windows)")
    p.add_argument("--mirror", type=float, default=0.0, help="probability of a left/right mirrored sample")
    p.add_argument("--time-warp", type=float, default=1.0,
                   help="playback-rate range [1/R, R] (log-uniform) of a resampled window; 1 = off")
    p.add_argument("--time-warp-prob", type=float, default=0.5, help="probability that a sample is time-warped")
    p.add_argument("--scale-aug", type=float, default=0.0,
                   help="body-scale augmentation: positions scaled by a factor uniform in [1-S, 1+S]")
    p.add_argument("--export-only", action="store_true",
                   help="write --out from the run's latest checkpoint (EMA weights) and exit, without training")
    a = p.parse_args()
    if not 0.0 <= a.observed_weight <= 1.0:
        p.error(f"--observed-weight must be in [0, 1], got {a.observed_weight}")
    if not 0.0 <= a.extra_none_prob < 1.0:
        p.error(f"--extra-none-prob must be in [0, 1) (1 would never observe an extra role), got {a.extra_none_prob}")
    for flag, v in (("--minutes", a.minutes), ("--session-minutes", a.session_minutes)):
        if not (math.isfinite(v) and v >= 0):
            p.error(f"{flag} takes minutes, a finite number >= 0 (0 = no limit), got {v}")
    return a


# The body-tracker roles a user may add to head and hands (docs/conventions.md) and the skeleton
# joint each observes (issue 44).
EXTRA_ROLES = {"hips": "Hips", "chest": "Chest", "left_foot": "Foot_L", "right_foot": "Foot_R",
               "left_knee": "LowerLeg_L", "right_knee": "LowerLeg_R", "left_elbow": "LowerArm_L",
               "right_elbow": "LowerArm_R"}


def read_clip_list(path):
    """The clip paths of a list file like training/heldout.txt, one path per line relative to the dataset root
    (dataset-1/....bvh). Lines as the C++ split reader reads them (motion/include/bodyd/motion/split_file.h):
    spaces, tabs and CRs at either end are not part of the path; a line then empty or starting with '#' is
    skipped; a list must name at least one clip. Exits with the file and line on a bad line."""
    out = []
    try:
        with open(path, newline="") as f:  # lines end at '\n' only, as std::getline's
            lines = f.read().split("\n")
    except OSError as e:
        sys.exit(f"--exclude-split {path}: cannot read: {e.strerror}")
    for n, line in enumerate(lines, 1):
        line = line.strip(" \t\r")
        if not line or line.startswith("#"):
            continue
        if os.path.isabs(line) or ".." in line.split("/"):
            sys.exit(f"{path}:{n}: '{line}' must be relative to the dataset root (e.g. dataset-1/NAME.bvh)")
        out.append(os.path.normpath(line))
    if not out:
        sys.exit(f"--exclude-split {path}: the list names no clips")
    return out


def excluded_clips(meta, files):
    """Boolean per meta["clips"]: its path ends with a path that one of files lists. Exits if a listed clip
    is not in the data (a list for another dataset would otherwise exclude nothing, silently)."""
    paths = [os.path.normpath(c["path"]) for c in meta["clips"]]
    out = np.zeros(len(paths), dtype=bool)
    for f in files:
        for rel in read_clip_list(f):
            hit = [i for i, q in enumerate(paths) if q == rel or q.endswith(os.sep + rel)]
            if not hit:
                sys.exit(f"--exclude-split {f}: clip '{rel}' is not in the dataset (export it from "
                         "splits/train.txt with bodyd-dataset, or fix the list)")
            out[hit] = True
    return out


def git_commit():
    try:
        return subprocess.check_output(["git", "rev-parse", "--short", "HEAD"], cwd=os.path.dirname(__file__),
                                       stderr=subprocess.DEVNULL).decode().strip()
    except Exception:
        return "unknown"


class Masker:
    """Random observation masks (B, W, D): trackers always (with random hand-loss spans), a random-length
    prefix of fully observed frames (the frames the online loop has already emitted), some unconditioned.
    Returns (mask, prefix (B, W): the prefix frames, trackers: the mask's tracker part alone)."""

    def __init__(self, meta, W, D, args, device):
        self.W, self.D, self.args, self.device = W, D, args, device
        te = meta["tracker_entries"]
        self.head = torch.tensor(te["head"], device=device)
        self.hands = [torch.tensor(te["left_hand"], device=device), torch.tensor(te["right_hand"], device=device)]
        # Extra roles: a joint's 9 entries are its position (3) then its rotation's first two columns (6).
        self.extra = []  # (name, position entries, rotation entries)
        for name in [r for r in args.extra_roles.split(",") if r]:
            if name not in EXTRA_ROLES:
                sys.exit(f"--extra-roles: unknown role {name!r}; expected some of {', '.join(EXTRA_ROLES)}")
            base = meta["joint_position_entries"][EXTRA_ROLES[name]][0]
            self.extra.append((name, torch.arange(base, base + 3, device=device),
                               torch.arange(base + 3, base + 9, device=device)))

    def span_visible(self, B, gen, prob):
        """(B, W) visibility: 1, or 0 over one random span with probability `prob` (tracking lost for a while)."""
        W, dev = self.W, self.device
        frame_idx = torch.arange(W, device=dev).view(1, W)
        vis = torch.ones(B, W, device=dev)
        drop = torch.rand(B, generator=gen, device=dev) < prob
        start = torch.randint(0, W, (B,), generator=gen, device=dev).view(B, 1)
        length = torch.randint(1, W + 1, (B,), generator=gen, device=dev).view(B, 1)
        span = (frame_idx >= start) & (frame_idx < start + length)
        vis[drop.view(B, 1) & span] = 0.0
        return vis

    def extra_masks(self, B, gen):
        """Per extra role: (B, W) position visibility and (B, W) rotation visibility."""
        a, dev = self.args, self.device
        out = []
        # Drawn only when asked for, so that without it the draws (and a run's masks) are the old ones.
        some = None
        if a.extra_none_prob > 0:
            some = (torch.rand(B, generator=gen, device=dev) >= a.extra_none_prob).float().view(B, 1)
        for _ in self.extra:
            tracked = (torch.rand(B, generator=gen, device=dev) < a.extra_role_prob).float().view(B, 1)
            if some is not None:
                tracked = tracked * some
            rot_only = (torch.rand(B, generator=gen, device=dev) < a.extra_rot_only_prob).float().view(B, 1)
            vis = self.span_visible(B, gen, a.extra_drop_prob) * tracked
            out.append((vis * (1 - rot_only), vis))
        return out

    def __call__(self, B, gen):
        W, D, a, dev = self.W, self.D, self.args, self.device
        m = torch.zeros(B, W, D, device=dev)
        m[:, :, self.head] = 1.0
        frame_idx = torch.arange(W, device=dev).view(1, W)
        for hand in self.hands:
            vis = self.span_visible(B, gen, a.hand_drop_prob)
            m[:, :, hand] = vis.unsqueeze(-1).expand(B, W, hand.numel())
        if self.extra:  # drawn after the hands: without --extra-roles the masks are the old ones, draw for draw
            for (_, pos, rot), (pvis, rvis) in zip(self.extra, self.extra_masks(B, gen)):
                m[:, :, pos] = pvis.unsqueeze(-1).expand(B, W, 3)
                m[:, :, rot] = rvis.unsqueeze(-1).expand(B, W, 6)
        # Prefix of fully observed frames: length W-1 (online case) or uniform in [0, W-1].
        full = torch.rand(B, generator=gen, device=dev) < a.full_prefix_prob
        plen = torch.randint(0, W, (B,), generator=gen, device=dev)
        plen = torch.where(full, torch.full_like(plen, W - 1), plen)
        prefix = (frame_idx < plen.view(B, 1)).float()  # (B, W)
        trackers = m.clone()  # the tracker part alone (--self-prefix reconstructs the past from it)
        m = torch.maximum(m, prefix.unsqueeze(-1).expand(B, W, D))
        uncond = torch.rand(B, generator=gen, device=dev) < a.uncond_prob
        m[uncond] = 0.0
        return m, prefix, trackers


# Left/right pairs of the skeleton (features::kJointNames).
MIRROR_PAIRS = [("Shoulder_L", "Shoulder_R"), ("UpperArm_L", "UpperArm_R"), ("LowerArm_L", "LowerArm_R"),
                ("Hand_L", "Hand_R"), ("UpperLeg_L", "UpperLeg_R"), ("LowerLeg_L", "LowerLeg_R"),
                ("Foot_L", "Foot_R"), ("Toes_L", "Toes_R")]
# Mirroring in global space (canonical frame, x -> -x): position p' = M p, rotation R' = M R C_j with
# M = diag(-1, 1, 1) and C_j = diag(c0, c1, c2) (det -1) the map between joint j's local axes and its
# mirror joint's. In 6D (the first two columns of R): col0' = c0 M col0, col1' = c1 M col1. The signs
# follow from this data's rig: the body's lateral axis is local Z for Spine..Head (Shoulders at +/-Z in the
# Chest's frame), local Y for Hips (legs at -/+Y), and a left limb's bones point along +X where the
# right limb's point along -X. With --mirror the signs are fitted on the data (fit_mirror_signs) and
# compared with these; on this data every joint's fit agrees (limbs: c0 = c1 = -1, i.e. C = -I).
MIRROR_SIGNS = {
    "Hips": (1, -1), "Spine": (1, 1), "Chest": (1, 1), "Neck": (1, 1), "Head": (1, 1),
}


def mirror_tables(meta, D, signs):
    """(perm, sign) with mirrored[..., i] = x[..., perm[i]] * sign[i] for one frame of D features."""
    names = list(meta["joint_position_entries"].keys())
    off = {n: meta["joint_position_entries"][n][0] for n in names}
    other = {n: n for n in names}
    for l_, r_ in MIRROR_PAIRS:
        other[l_], other[r_] = r_, l_
    perm = torch.arange(D)
    sign = torch.ones(D)
    for n in names:
        c0, c1 = signs[n]
        dst, src = off[other[n]], off[n]
        for k in range(9):
            perm[dst + k] = src + k
        sign[dst:dst + 9] = torch.tensor([-1, 1, 1, -c0, c0, c0, -c1, c1, c1], dtype=torch.float32)
    c = meta["contact_entries"]
    perm[c[0]], perm[c[1]] = c[1], c[0]
    return perm, sign


def fit_mirror_signs(meta, raw, D):
    """For each joint, the (c0, c1) whose mirrored mean rotation is closest to its mirror joint's mean rotation
    (the data holds left- and right-handed versions of most motions, so the two distributions agree)."""
    names = list(meta["joint_position_entries"].keys())
    off = {n: meta["joint_position_entries"][n][0] for n in names}
    other = {n: n for n in names}
    for l_, r_ in MIRROR_PAIRS:
        other[l_], other[r_] = r_, l_
    frames = torch.from_numpy(np.ascontiguousarray(raw[::50, -1])).double()  # newest frames of a subset
    mean = frames.mean(0)
    M = torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)
    out, report = {}, []
    for n in names:
        src, dst = off[n], off[other[n]]
        best = None
        for c0 in (1, -1):
            for c1 in (1, -1):
                m0 = c0 * M * mean[src + 3:src + 6]
                m1 = c1 * M * mean[src + 6:src + 9]
                d = float((m0 - mean[dst + 3:dst + 6]).norm() + (m1 - mean[dst + 6:dst + 9]).norm())
                if best is None or d < best[0]:
                    best = (d, (c0, c1))
        out[n] = best[1]
        report.append(f"{n}:{best[1]} d={best[0]:.3f}")
    return out, report


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
    N, Ws, D = data.shape
    W = a.window or Ws
    assert D == meta["dim"], "dataset dim disagrees with its metadata"
    assert W <= Ws, f"--window {W} is longer than the dataset's windows ({Ws})"
    # Hold out every Nth clip (by clip order) for monitoring; the validation split is never touched here.
    clip_of_window = np.repeat(np.arange(len(meta["clips"])), [c["windows"] for c in meta["clips"]])
    hold = (clip_of_window % a.holdout_every) == (a.holdout_every - 1)
    # --exclude-split clips (training/style-heldout.txt) are neither trained on nor part of the monitor.
    excl_clip = excluded_clips(meta, a.exclude_split)
    excl = excl_clip[clip_of_window]
    train_idx, hold_idx = np.nonzero(~hold & ~excl)[0], np.nonzero(hold & ~excl)[0]
    if a.exclude_split:
        print(f"excluded: {int(excl_clip.sum())} clips ({int(excl.sum())} windows) listed in "
              f"{', '.join(a.exclude_split)}", flush=True)
    # Raw features stay in memory (augmentations act on them); each batch is normalised when drawn.
    x_raw = torch.from_numpy(np.ascontiguousarray(data)).to(dev)
    init = None
    if a.init_from:
        init = load_model(a.init_from)
        cfg = init[0].config()
        if (cfg["W"], cfg["D"]) != (W, D):
            sys.exit(f"--init-from {a.init_from}: model W={cfg['W']} D={cfg['D']}, data/--window W={W} D={D}")
        a.arch = init[0].ARCHITECTURE
        for k, v in cfg.items():
            if k not in ("W", "D"):
                setattr(a, k, v)
        mean, std = init[1]["norm.mean"], init[1]["norm.std"]
    elif a.init_trunk:
        if a.arch != TcnMlp.ARCHITECTURE:
            sys.exit("--init-trunk is for --arch tcnmlp-v1")
        trunk = load_model(a.init_trunk)
        tcfg = trunk[0].config()
        if trunk[0].ARCHITECTURE != MlpWin.ARCHITECTURE or (tcfg["W"], tcfg["D"]) != (a.N, D):
            sys.exit(f"--init-trunk {a.init_trunk}: need an mlpwin-v1 model with W = --N = {a.N} and D = {D}, "
                     f"got {trunk[0].ARCHITECTURE} W={tcfg['W']} D={tcfg['D']}")
        a.E, a.H, a.L, a.T = tcfg["E"], tcfg["H"], tcfg["L"], tcfg["T"]
        mean, std = trunk[1]["norm.mean"], trunk[1]["norm.std"]
    else:
        newest = x_raw[torch.from_numpy(train_idx).to(dev), Ws - W:].reshape(-1, D)
        mean = newest.mean(0).cpu()
        std = newest.std(0).clamp_min(0.01).cpu()
        del newest
    mean_d, std_d = mean.to(dev), std.to(dev)
    train_idx_t = torch.from_numpy(train_idx).to(dev)
    hold_idx_t = torch.from_numpy(hold_idx).to(dev)
    print(f"data: {N} windows of {Ws}x{D}, model window {W} ({len(train_idx)} train, {len(hold_idx)} held out) on {dev}",
          flush=True)

    # Sampling weights: with --balance, dataset-1 windows make up that fraction of each batch.
    is_d1 = np.array(["dataset-1" in os.path.basename(c["path"]) for c in meta["clips"]])[clip_of_window]
    sample_p = None
    if a.balance > 0:
        d1 = is_d1[train_idx]
        w_ = np.where(d1, a.balance / max(1, d1.sum()), (1 - a.balance) / max(1, (~d1).sum()))
        sample_p = torch.from_numpy(w_ / w_.sum()).to(dev)
        print(f"balance: dataset-1 {d1.sum()} of {len(d1)} windows ({d1.mean():.1%}), drawn with p = {a.balance}",
              flush=True)
    mirror_perm = mirror_sign = None
    if a.mirror > 0:
        signs, report = fit_mirror_signs(meta, data, D)
        for n_, sg in MIRROR_SIGNS.items():
            if signs[n_] != sg:
                print(f"warning: fitted mirror signs of {n_} {signs[n_]} differ from the rig's {sg}", flush=True)
        print("mirror signs (fitted on the data): " + ", ".join(report), flush=True)
        mirror_perm, mirror_sign = (t.to(dev) for t in mirror_tables(meta, D, signs))
    pos_cols = torch.tensor(sorted(i for v in meta["joint_position_entries"].values() for i in v), device=dev)
    contact_cols = torch.tensor(meta["contact_entries"], device=dev)

    def draw(idx, g, augment):
        """Normalised (B, W, D) windows of dataset windows idx, augmented when `augment`."""
        B = idx.shape[0]
        raw = x_raw[idx]                                                      # (B, Ws, D)
        if augment and a.time_warp > 1.0:
            # Resample the window at rate r ending at its newest frame (the canonical frame's): frame w is
            # at source frame Ws-1 - r*(W-1-w), linearly interpolated (6D columns too; decoding re-orthonormalises).
            lr = math.log(a.time_warp)
            r = torch.exp((torch.rand(B, generator=g, device=dev) * 2 - 1) * lr)
            r = torch.where(torch.rand(B, generator=g, device=dev) < a.time_warp_prob, r, torch.ones_like(r))
            f = (Ws - 1) - r.view(B, 1) * torch.arange(W - 1, -1, -1, device=dev).view(1, W)
            f = f.clamp(0, Ws - 1)
            lo = f.floor().long()
            hi = (lo + 1).clamp(max=Ws - 1)
            u = (f - lo).unsqueeze(-1)
            ar = torch.arange(B, device=dev).view(B, 1)
            x = (1 - u) * raw[ar, lo] + u * raw[ar, hi]
            x[:, :, contact_cols] = (x[:, :, contact_cols] > 0.5).float()
        else:
            x = raw[:, Ws - W:]
        if augment and mirror_perm is not None:
            flip = torch.rand(B, generator=g, device=dev) < a.mirror
            if bool(flip.any()):
                x = x.clone()
                x[flip] = x[flip][:, :, mirror_perm] * mirror_sign
        if augment and a.scale_aug > 0:
            sc = 1 + (torch.rand(B, 1, 1, generator=g, device=dev) * 2 - 1) * a.scale_aug
            x = x.clone()
            x[:, :, pos_cols] = x[:, :, pos_cols] * sc
        return (x - mean_d) / std_d

    net = make_net(a, W, D).to(dev)
    ema = make_net(a, W, D).to(dev)
    if init is not None:
        net.load_state_dict(init[0].state_dict())
        print(f"initialised from {a.init_from}", flush=True)
    if init is None and a.init_trunk:
        own = net.state_dict()
        for k, v in trunk[0].state_dict().items():
            own[k] = v
        own["ctx.weight"].zero_()
        own["ctx.bias"].zero_()
        net.load_state_dict(own)
        print(f"trunk initialised from {a.init_trunk}", flush=True)
    ema.load_state_dict(net.state_dict())
    for p in ema.parameters():
        p.requires_grad_(False)
    opt = torch.optim.AdamW(net.parameters(), lr=a.lr, weight_decay=a.weight_decay)
    ab = cosine_alpha_bars(a.T).to(dev)
    masker = Masker(meta, W, D, a, dev)
    gen = torch.Generator(device=dev)
    gen.manual_seed(a.seed)
    nparams = sum(p.numel() for p in net.parameters())
    cfg_text = " ".join(f"{k}={v}" for k, v in net.config().items())
    extra = f", receptive field {net.receptive_field()} frames" if hasattr(net, "receptive_field") else ""
    print(f"model: {net.ARCHITECTURE} {cfg_text}, {nparams / 1e6:.2f} M parameters{extra}", flush=True)

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
        if "norm_mean" in ck:
            mean, std = ck["norm_mean"], ck["norm_std"]
            mean_d, std_d = mean.to(dev), std.to(dev)
        print(f"resumed from {ckpt_path} at step {step}", flush=True)

    def lr_at(s):
        # Linear warm-up, then cosine decay over the run; with --minutes the decay follows whichever of
        # steps and wall time runs out first, so a time-limited run still ends at a low learning rate.
        warm = a.warmup
        if s < warm:
            return a.lr * (s + 1) / warm
        frac = (s - warm) / max(1, a.steps - warm)
        if a.minutes:
            frac = max(frac, (time.time() - t0 + wall_before) / 60.0 / a.minutes)
        return a.lr * 0.5 * (1 + math.cos(math.pi * min(1.0, frac)))

    def strapped(obs, g, joints=None, sel=None):
        """obs with each listed joint seen through a wrong mounting: a constant offset per sample in the joint's
        own frame, position R o (o ~ N(0, cm) per axis) and rotation R Q (Q about a random rotation vector
        ~ N(0, deg) per axis). `joints`: (position entries, rotation entries, cm, deg) per joint; default the
        extra roles with --extra-mount-cm / --extra-mount-deg. `sel` (B,): only those samples."""
        B = obs.shape[0]
        raw = obs * std_d + mean_d
        if joints is None:
            joints = [(pos, rot, a.extra_mount_cm, a.extra_mount_deg) for _, pos, rot in masker.extra]
        for pos, rot, cm, deg in joints:
            if sel is not None:
                before_pos, before_rot = raw[:, :, pos].clone(), raw[:, :, rot].clone()
            c0 = torch.nn.functional.normalize(raw[:, :, rot[:3]], dim=-1)
            c1 = raw[:, :, rot[3:]]
            c1 = torch.nn.functional.normalize(c1 - (c1 * c0).sum(-1, keepdim=True) * c0, dim=-1)
            c2 = torch.cross(c0, c1, dim=-1)
            o = torch.randn(B, 1, 3, generator=g, device=dev) * (cm / 100.0)
            raw[:, :, pos] = raw[:, :, pos] + c0 * o[..., 0:1] + c1 * o[..., 1:2] + c2 * o[..., 2:3]
            v = torch.randn(B, 3, generator=g, device=dev) * math.radians(deg)
            angle = v.norm(dim=-1, keepdim=True).clamp_min(1e-9)
            k = v / angle
            K = torch.zeros(B, 3, 3, device=dev)
            K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
            K = K - K.transpose(1, 2)
            sa, ca = torch.sin(angle).view(B, 1, 1), torch.cos(angle).view(B, 1, 1)
            Q = (torch.eye(3, device=dev).expand(B, 3, 3) + sa * K + (1 - ca) * (K @ K)).view(B, 1, 3, 3)
            raw[:, :, rot[:3]] = c0 * Q[..., 0, 0:1] + c1 * Q[..., 1, 0:1] + c2 * Q[..., 2, 0:1]
            raw[:, :, rot[3:]] = c0 * Q[..., 0, 1:2] + c1 * Q[..., 1, 1:2] + c2 * Q[..., 2, 1:2]
            if sel is not None:  # the other samples keep their joint as it was
                keep = (~sel).view(B, 1, 1)
                raw[:, :, pos] = torch.where(keep, before_pos, raw[:, :, pos])
                raw[:, :, rot] = torch.where(keep, before_rot, raw[:, :, rot])
        return (raw - mean_d) / std_d

    def loss_on(model, idx, g, augment=False):
        x0 = draw(idx, g, augment)
        B = x0.shape[0]
        m, prefix, trackers = masker(B, g)
        t = torch.randint(0, a.T, (B,), generator=g, device=dev)
        noise = torch.randn(x0.shape, generator=g, device=dev)
        abt = ab[t].view(B, 1, 1)
        xt = abt.sqrt() * x0 + (1 - abt).sqrt() * noise
        # Observations as the online loop gives them: emitted frames carry the model's own errors,
        # trackers their noise (both small, in normalised units).
        obs = x0 + a.prefix_noise * prefix.unsqueeze(-1) * torch.randn(x0.shape, generator=g, device=dev)
        obs = obs + a.tracker_noise * torch.randn(x0.shape, generator=g, device=dev)
        if masker.extra and (a.extra_mount_cm > 0 or a.extra_mount_deg > 0):
            # Only the trackers' frames: a prefix frame is the emitted body, not a tracker's view of it.
            pf = prefix.unsqueeze(-1)
            obs = pf * obs + (1 - pf) * strapped(obs, g)
        if a.xr_mount_prob > 0:
            # The headset and controllers through a wrong mounting, in every frame: the emitted past holds the
            # head and hands where the trackers put them (the runtime's body solver), so the prefix does too.
            xr = [(masker.head[:3], masker.head[3:], a.head_mount_cm, a.head_mount_deg)] + \
                 [(h[:3], h[3:], a.hand_mount_cm, a.hand_mount_deg) for h in masker.hands]
            obs = strapped(obs, g, xr, torch.rand(B, generator=g, device=dev) < a.xr_mount_prob)
        if augment and a.self_prefix > 0:
            # The online loop's past is what it emitted: the model's own reconstruction, trackers exact. Here it
            # is approximated by one reconstruction of the whole window from its trackers (no past), by the EMA
            # weights, with the observed tracker entries imputed as the runtime does.
            sel = (torch.rand(B, generator=g, device=dev) < a.self_prefix) & (prefix.sum(1) > 0) \
                & (m.flatten(1).sum(1) > 0)
            if bool(sel.any()):
                with torch.no_grad():
                    ema.eval()
                    roll = ddim_sample(ema, x0[sel], trackers[sel], ab, a.self_prefix_steps, g)
                pf = prefix[sel].unsqueeze(-1)
                obs = obs.clone()
                obs[sel] = pf * roll + (1 - pf) * obs[sel]
        inp = m * obs + (1 - m) * xt
        pred = model(inp, m, t)
        w = 1.0 - (1.0 - a.observed_weight) * m  # the unobserved part is what the model is for
        return ((pred - x0) ** 2 * w).sum() / w.sum()

    # Monitor: the online case (all frames but the newest observed, trackers in the newest), K-step DDIM,
    # error of the newest frame's joint positions in cm (all joints / lower body), on held-out clips.
    pos_entries = meta["joint_position_entries"]
    lower_names = ["Hips", "UpperLeg_L", "UpperLeg_R", "LowerLeg_L", "LowerLeg_R", "Foot_L", "Foot_R", "Toes_L", "Toes_R"]
    pos_idx = torch.tensor([pos_entries[n] for n in pos_entries], device=dev)            # (21, 3)
    lower_idx = torch.tensor([pos_entries[n] for n in lower_names], device=dev)
    mon_idx = hold_idx_t[torch.randperm(len(hold_idx_t), generator=torch.Generator().manual_seed(7))[:512].to(dev)] \
        if len(hold_idx_t) else None
    # The same on the --exclude-split clips (the held-out styles): watched, never trained on.
    excl_idx_t = torch.from_numpy(np.nonzero(excl)[0]).to(dev)
    style_idx = excl_idx_t[torch.randperm(len(excl_idx_t), generator=torch.Generator().manual_seed(7))[:512].to(dev)] \
        if len(excl_idx_t) else None

    def monitor(model, idx, extra=()):
        """Newest-frame error with head, hands and the `extra` roles ((name, pos, rot) of masker.extra) tracked."""
        x0 = draw(idx, None, False)
        B = x0.shape[0]
        m = torch.zeros_like(x0)
        m[:, :W - 1, :] = 1.0
        m[:, W - 1, masker.head] = 1.0
        for hand in masker.hands:
            m[:, W - 1, hand] = 1.0
        for _, pos, rot in extra:
            m[:, W - 1, pos] = 1.0
            m[:, W - 1, rot] = 1.0
        g = torch.Generator(device=dev)
        g.manual_seed(5)
        out = ddim_sample(model, x0, m, ab, 4, g)
        real_out = out[:, W - 1] * std_d + mean_d
        real_x0 = x0[:, W - 1] * std_d + mean_d
        def err(idx):
            return ((real_out[:, idx] - real_x0[:, idx]).norm(dim=-1)).mean().item() * 100
        return err(pos_idx), err(lower_idx)

    def save_checkpoint():
        tmp = ckpt_path + ".tmp"
        torch.save({"net": net.state_dict(), "ema": ema.state_dict(), "opt": opt.state_dict(),
                    "gen": gen.get_state(), "torch_rng": torch.get_rng_state(), "step": step,
                    "wall_s": time.time() - t0 + wall_before, "args": vars(a),
                    "norm_mean": mean, "norm_std": std}, tmp)
        os.replace(tmp, ckpt_path)

    log = open(os.path.join(a.run_dir, "log.txt"), "a")
    last_print, seen = t0, 0
    hold_gen = torch.Generator(device=dev)
    while step < a.steps and not a.export_only:
        if a.minutes and (time.time() - t0 + wall_before) / 60.0 >= a.minutes:
            print(f"\nwall-time limit of {a.minutes} min reached at step {step}", flush=True)
            break
        for g_ in opt.param_groups:
            g_["lr"] = lr_at(step)
        if sample_p is None:
            idx = train_idx_t[torch.randint(0, len(train_idx_t), (a.batch,), generator=gen, device=dev)]
        else:
            idx = train_idx_t[torch.multinomial(sample_p, a.batch, replacement=True, generator=gen)]
        net.train()
        loss = loss_on(net, idx, gen, augment=True)
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
                all_cm, lower_cm = monitor(ema, mon_idx)
                style = (" excluded_newest_frame_cm all {:.2f} lower {:.2f}".format(*monitor(ema, style_idx))
                         if style_idx is not None else "")
                # With every extra role tracked too (hips, feet, ...): what a user with body trackers gets.
                hips_feet = [e for e in masker.extra if e[0] in ("hips", "left_foot", "right_foot")]
                if hips_feet and style_idx is not None:
                    style += " excluded_hips_feet_cm all {:.2f} lower {:.2f}".format(*monitor(ema, style_idx, hips_feet))
            msg = (f"step {step} train_loss {loss.item():.5f} holdout_loss_ema {hl:.5f} "
                   f"holdout_newest_frame_cm all {all_cm:.2f} lower {lower_cm:.2f}{style} "
                   f"wall_min {(time.time() - t0 + wall_before) / 60:.1f}")
            print("\n" + msg, flush=True)
            log.write(msg + "\n")
            log.flush()
        if step % a.ckpt_every == 0 or step == a.steps:
            save_checkpoint()
        if a.session_minutes and step < a.steps and (time.time() - t0) / 60.0 >= a.session_minutes:
            if step % a.ckpt_every:
                save_checkpoint()
            msg = (f"session budget of {a.session_minutes:g} min reached at step {step} of {a.steps}; "
                   f"checkpoint {ckpt_path} saved, {a.out} not written; give the same command again to continue")
            print("\n" + msg, flush=True)
            log.write(msg + "\n")
            log.close()
            sys.exit(3)

    wall_s = time.time() - t0 + wall_before
    hw = torch.cuda.get_device_name(0) if dev.type == "cuda" else f"CPU ({platform.processor() or platform.machine()}, {torch.get_num_threads()} threads)"
    provenance = {
        "data": "Bandai Namco Research Motion Dataset (CC BY-NC 4.0), " + os.path.basename(a.data),
        "windows_total": int(N), "windows_train": int(len(train_idx)), "holdout_every_clip": a.holdout_every,
        "excluded_clips": int(excl_clip.sum()), "exclude_split": a.exclude_split,
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
