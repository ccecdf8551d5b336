#!/usr/bin/env python3
"""PyTorch reference timing of the PoseNet training step, for comparison with the criterion
benchmark `posenet` beside this file (not run by CI: it needs `pip install torch`).

PoseNet (authors' design):
  time t in [-1, 1], embedding g(t) = [t, sin(2^k pi t) k<5, cos(2^k pi t) k<5]  (11 dims)
  two independent MLPs (translation: 3 outputs, rotation: 4 outputs), 8 Linear layers, width 256:
    L0 11->256, L1-L3 256->256, L4 (256+11)->256 on concat[h, g], L5-L6 256->256, L7 256->out
  activation after L0..L6 (ReLU for "plain", Softplus for derivative cases)
  heads: p = tanh(o); q_w = 1 - tanh(r0), q_xyz = tanh(r1..3), q = q / |q|
  init: Xavier-uniform weights, zero bias; last layer weights U(0, 1e-6), zero bias
One training step = forward, loss, backward, Adam step (lr 1e-3 translation / 2e-4 rotation).
  plain   : L1(p) + L1(q)
  first   : + L1(dp/dt) + L1(dq/dt)           (autograd.grad, create_graph=True, sum trick)
  second  : + L1(d2p/dt2) + L1(d2q/dt2)       (grad of each first-derivative component again)

Usage:
  python posenet_ref.py --threads 2 [--batches 64,1024,4096,16384] [--modes plain,first,second]
  python posenet_ref.py --check        # finite-difference sanity check of the derivatives
  python posenet_ref.py --matmul       # PyTorch's own f32 product rate, 4096x256 @ 256x256
"""
import argparse
import json
import math
import os
import statistics
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

WIDTH = 256
NFREQ = 5
EMB = 1 + 2 * NFREQ  # 11


def embed(t):
    """t: (B,1) -> (B,11) = [t, sin(2^k pi t), cos(2^k pi t)]."""
    freqs = (2.0 ** torch.arange(NFREQ, dtype=t.dtype, device=t.device)) * math.pi
    a = t * freqs  # (B,5)
    return torch.cat([t, torch.sin(a), torch.cos(a)], dim=1)


class MLP(nn.Module):
    def __init__(self, out_dim, act):
        super().__init__()
        dims = [(EMB, WIDTH), (WIDTH, WIDTH), (WIDTH, WIDTH), (WIDTH, WIDTH),
                (WIDTH + EMB, WIDTH), (WIDTH, WIDTH), (WIDTH, WIDTH), (WIDTH, out_dim)]
        self.layers = nn.ModuleList(nn.Linear(i, o) for i, o in dims)
        self.act = act
        for k, lin in enumerate(self.layers):
            if k < 7:
                nn.init.xavier_uniform_(lin.weight)
            else:
                nn.init.uniform_(lin.weight, 0.0, 1e-6)
            nn.init.zeros_(lin.bias)

    def forward(self, g):
        h = g
        for k in range(7):
            if k == 4:
                h = torch.cat([h, g], dim=1)
            h = self.act(self.layers[k](h))
        return self.layers[7](h)


class PoseNet(nn.Module):
    def __init__(self, act):
        super().__init__()
        self.trans = MLP(3, act)
        self.rot = MLP(4, act)

    def forward(self, t):
        g = embed(t)
        p = torch.tanh(self.trans(g))
        r = self.rot(g)
        q = torch.cat([1.0 - torch.tanh(r[:, :1]), torch.tanh(r[:, 1:])], dim=1)
        q = q / q.norm(dim=1, keepdim=True)
        return p, q


def dt(y, t):
    """Per-sample d y / d t for every column of y (B,k); sum trick, create_graph=True."""
    cols = [torch.autograd.grad(y[:, k].sum(), t, create_graph=True)[0] for k in range(y.shape[1])]
    return torch.cat(cols, dim=1)


def make(mode, B, seed=0, dtype=torch.float32):
    torch.manual_seed(seed)
    act = nn.ReLU() if mode == "plain" else nn.Softplus()
    net = PoseNet(act).to(dtype)
    opt = torch.optim.Adam([
        {"params": net.trans.parameters(), "lr": 1e-3},
        {"params": net.rot.parameters(), "lr": 2e-4},
    ])
    t = (torch.rand(B, 1, dtype=dtype) * 2 - 1)
    order = {"plain": 0, "first": 1, "second": 2}[mode]
    tg = [(torch.randn(B, 3, dtype=dtype), torch.randn(B, 4, dtype=dtype)) for _ in range(order + 1)]
    return net, opt, t, tg, order


def loss_fn(net, t, tg, order):
    t = t.detach().requires_grad_(order > 0)
    p, q = net(t)
    loss = (p - tg[0][0]).abs().mean() + (q - tg[0][1]).abs().mean()
    if order >= 1:
        dp, dq = dt(p, t), dt(q, t)
        loss = loss + (dp - tg[1][0]).abs().mean() + (dq - tg[1][1]).abs().mean()
        if order >= 2:
            ddp, ddq = dt(dp, t), dt(dq, t)
            loss = loss + (ddp - tg[2][0]).abs().mean() + (ddq - tg[2][1]).abs().mean()
    return loss


def step(net, opt, t, tg, order):
    """Returns (total seconds, adam seconds)."""
    t0 = time.perf_counter()
    opt.zero_grad(set_to_none=True)
    loss = loss_fn(net, t, tg, order)
    loss.backward()
    t1 = time.perf_counter()
    opt.step()
    t2 = time.perf_counter()
    return t2 - t0, t2 - t1


# ---------- machine-quietness monitoring ----------
CLK = os.sysconf("SC_CLK_TCK")


def loadavg1():
    with open("/proc/loadavg") as f:
        return float(f.read().split()[0])


def cpu_busy_s():
    """System-wide busy CPU seconds (all cores) from /proc/stat."""
    with open("/proc/stat") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    total = sum(v[:8])
    idle = v[3] + v[4]
    return (total - idle) / CLK


def self_cpu_s():
    t = os.times()
    return t.user + t.system


class Foreign:
    """CPU cores used by processes other than this one, averaged over the window."""

    def __enter__(self):
        self.w0, self.b0, self.s0 = time.perf_counter(), cpu_busy_s(), self_cpu_s()
        return self

    def __exit__(self, *a):
        w = time.perf_counter() - self.w0
        self.cores = max(0.0, (cpu_busy_s() - self.b0) - (self_cpu_s() - self.s0)) / w


def foreign_idle(window=3.0):
    with Foreign() as f:
        time.sleep(window)
    return f.cores


def wait_loadavg(limit=0.5, sleep=20, max_wait=600):
    t0 = time.time()
    while loadavg1() >= limit and time.time() - t0 < max_wait:
        log(f"  loadavg {loadavg1():.2f} >= {limit}, sleeping {sleep}s")
        time.sleep(sleep)
    return loadavg1()


def wait_foreign_quiet(limit=0.1, max_wait=600):
    t0 = time.time()
    while True:
        c = foreign_idle()
        if c < limit or time.time() - t0 > max_wait:
            return c
        log(f"  foreign CPU {c:.2f} cores >= {limit}, waiting")
        time.sleep(10)


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def measure(mode, B, warmup=3, min_steps=7, min_time=3.0, max_steps=60):
    net, opt, t, tg, order = make(mode, B)
    for _ in range(warmup):
        step(net, opt, t, tg, order)
    tot, adam, fgn = [], [], []
    la0 = loadavg1()
    w0 = time.perf_counter()
    with Foreign() as fall:
        while len(tot) < min_steps or (time.perf_counter() - w0 < min_time and len(tot) < max_steps):
            with Foreign() as f:
                a, b = step(net, opt, t, tg, order)
            tot.append(a); adam.append(b); fgn.append(f.cores)
    la1 = loadavg1()
    return dict(mode=mode, B=B, threads=torch.get_num_threads(), n=len(tot),
                median_ms=1e3 * statistics.median(tot), min_ms=1e3 * min(tot),
                max_ms=1e3 * max(tot), adam_median_ms=1e3 * statistics.median(adam),
                fwdbwd_median_ms=1e3 * (statistics.median(tot) - statistics.median(adam)),
                foreign_cores=fall.cores, foreign_max_step=max(fgn),
                loadavg_start=la0, loadavg_end=la1)


def check():
    """Finite-difference check of dp/dt, d2p/dt2 (float64, softplus)."""
    net, _, _, _, _ = make("second", 4, dtype=torch.float64)
    # make outputs non-trivial: perturb last layers
    with torch.no_grad():
        for m in (net.trans, net.rot):
            m.layers[7].weight.normal_(0, 0.1)
    t = torch.linspace(-0.9, 0.9, 4, dtype=torch.float64).unsqueeze(1).requires_grad_(True)
    p, q = net(t)
    dp, dq = dt(p, t), dt(q, t)
    ddp, ddq = dt(dp, t), dt(dq, t)
    h = 1e-6

    def d1(x):
        x = x.detach().requires_grad_(True)
        a, b = net(x)
        return torch.cat([dt(a, x), dt(b, x)], 1).detach()

    with torch.no_grad():
        pp, qp = net(t + h); pm, qm = net(t - h)
    e1 = max((dp - (pp - pm) / (2 * h)).abs().max().item(), (dq - (qp - qm) / (2 * h)).abs().max().item())
    e2 = (torch.cat([ddp, ddq], 1) - (d1(t + h) - d1(t - h)) / (2 * h)).abs().max().item()
    print(f"FD check: max|d1 err|={e1:.2e}  max|d2 err|={e2:.2e}  "
          f"(|dp|max={dp.abs().max().item():.3f}, |ddp|max={ddp.abs().max().item():.3f})")
    nparams = sum(x.numel() for x in net.parameters())
    print(f"params: {nparams}")
    assert e1 < 1e-6 and e2 < 1e-5


def matmul_rate(threads):
    """Best-of-20 GFLOP/s of one 4096x256 @ 256x256 f32 product (the shape of a hidden layer)."""
    torch.set_num_threads(threads)
    a, b = torch.rand(4096, WIDTH), torch.rand(WIDTH, WIDTH)
    out = torch.empty(4096, WIDTH)
    for _ in range(3):
        torch.matmul(a, b, out=out)
    best = math.inf
    for _ in range(20):
        t0 = time.perf_counter()
        torch.matmul(a, b, out=out)
        best = min(best, time.perf_counter() - t0)
    return 2 * 4096 * WIDTH * WIDTH / best / 1e9


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--batches", default="64,1024,4096,16384")
    ap.add_argument("--deriv-batches", default="64,1024,4096")
    ap.add_argument("--modes", default="plain,first,second")
    ap.add_argument("--out", default=None, help="append JSON lines here")
    ap.add_argument("--foreign-limit", type=float, default=0.15,
                    help="rerun a config if other processes used more CPU cores than this")
    ap.add_argument("--loadavg-limit", type=float, default=0.5,
                    help="initial wait until the 1-min load average is below this (our own previous"
                         " run inflates it; the per-config foreign-CPU check is the real guard)")
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--matmul", action="store_true")
    a = ap.parse_args()
    if a.check:
        check()
        return
    if a.matmul:
        for threads in (1, a.threads):
            print(f"matmul 4096x256x256, {threads} thread(s): {matmul_rate(threads):.1f} GFLOP/s")
        return
    torch.set_num_threads(a.threads)
    log(f"torch {torch.__version__}, threads {torch.get_num_threads()}, "
        f"cpu capability {torch.backends.cpu.get_cpu_capability()}")
    log(f"initial loadavg wait -> {wait_loadavg(a.loadavg_limit):.2f}")
    for mode in a.modes.split(","):
        bs = a.batches if mode == "plain" else a.deriv_batches
        for B in [int(x) for x in bs.split(",")]:
            for attempt in range(4):
                fq = wait_foreign_quiet()
                r = measure(mode, B)
                r["attempt"] = attempt
                r["foreign_before"] = fq
                ok = r["foreign_cores"] <= a.foreign_limit
                log(json.dumps(r))
                if ok:
                    break
                log(f"  disturbed (foreign {r['foreign_cores']:.2f} cores) -> rerun")
            print(json.dumps(r), flush=True)
            if a.out:
                with open(a.out, "a") as f:
                    f.write(json.dumps(r) + "\n")


if __name__ == "__main__":
    main()
