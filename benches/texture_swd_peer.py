#!/usr/bin/env python3
"""The peer of swd-loss's texture loss: the same loss as a PyTorch user would write it.

Laplacian pyramid (5x5 binomial blur, edges replicated, every other pixel kept; band-pass
levels G_l - blur(nearest_up(G_{l+1})) and the coarsest Gaussian level last), 7x7 patches of
each level (`unfold`, or a gather of random patch positions), K random unit directions per
level, torch.sort, squared W2 between the sorted projections (equal counts: mean of squared
differences), mean over directions, sum over levels. Timed as swd-loss's criterion bench
`swd/texture_fwd_bwd` times it: one float32 image of `res x res` against a fixed target, forward
and backward to the image, median of `--repeats` calls after a warm-up. One JSON line per case.

    /tmp/peer/venv/bin/python benches/texture_swd_peer.py --threads 2
"""
import argparse
import json
import time

import torch
import torch.nn.functional as F


def blur(x, stride):
    k = torch.tensor([1.0, 4.0, 6.0, 4.0, 1.0], dtype=x.dtype) / 16
    c = x.shape[1]
    x = F.conv2d(F.pad(x, (0, 0, 2, 2), mode="replicate"), k.view(1, 1, 5, 1).repeat(c, 1, 1, 1), groups=c)
    x = x[:, :, ::stride]
    x = F.conv2d(F.pad(x, (2, 2, 0, 0), mode="replicate"), k.view(1, 1, 1, 5).repeat(c, 1, 1, 1), groups=c)
    return x[:, :, :, ::stride]


def laplacian(img, levels):
    g = [img]
    for _ in range(1, levels):
        g.append(blur(g[-1], 2))
    out = []
    for fine, coarse in zip(g[:-1], g[1:]):
        up = coarse.repeat_interleave(2, 2).repeat_interleave(2, 3)
        out.append(fine - blur(up, 1)[:, :, : fine.shape[2], : fine.shape[3]])
    out.append(g[-1])
    return out


def project(level, dirs, p, points, gen):
    """(B, K, P): all patches (points None) or `points` random ones, through `dirs` (K, C p^2)."""
    b, c, h, w = level.shape
    oh, ow = h - p + 1, w - p + 1
    if points is None or points >= oh * ow:
        cols = F.unfold(level, p)
    else:
        pos = torch.randperm(oh * ow, generator=gen)[:points].sort().values
        ys, xs = pos // ow, pos % ow
        dy = torch.arange(p).view(p, 1, 1)
        dx = torch.arange(p).view(1, p, 1)
        idx = ((ys.view(1, 1, -1) + dy) * w + xs.view(1, 1, -1) + dx).reshape(-1)
        cols = level.reshape(b, c, h * w)[:, :, idx].reshape(b, c * p * p, -1)
    return dirs @ cols


def texture_loss(gen_levels, tgt_levels, slices, points, gen, p=7):
    total = 0.0
    for gl, tl in zip(gen_levels, tgt_levels):
        dirs = torch.randn(slices, gl.shape[1] * p * p, generator=gen)
        dirs = dirs / dirs.norm(dim=1, keepdim=True)
        xs = project(gl, dirs, p, points, gen).sort(-1).values
        ys = project(tl, dirs, p, points, gen).sort(-1).values
        total = total + ((xs - ys) ** 2).mean(-1).mean(-1)
    return total.mean()


def bench(res, slices, points, repeats, levels=3):
    gen = torch.Generator().manual_seed(0)
    target = torch.rand(1, 3, res, res, generator=gen)
    image = torch.rand(1, 3, res, res, generator=gen).requires_grad_(True)
    tgt_levels = [t.detach() for t in laplacian(target, levels)]

    def step():
        image.grad = None
        loss = texture_loss(laplacian(image, levels), tgt_levels, slices, points, gen)
        loss.backward()

    step()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        step()
        times.append(time.perf_counter() - t0)
    times.sort()
    return times[len(times) // 2]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=10)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    for res, slices, points in [(64, 64, None), (320, 64, None), (320, 128, 4096), (320, 64, 8192)]:
        s = bench(res, slices, points, a.repeats)
        print(json.dumps(dict(peer="torch", torch=torch.__version__, threads=a.threads, res=res,
                              slices=slices, points=points or "all", fwd_bwd_s=s)), flush=True)


if __name__ == "__main__":
    main()
