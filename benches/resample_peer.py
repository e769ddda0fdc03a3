#!/usr/bin/env python3
"""The peer of radiance-volume's `resample_tensor`: the trilinear resampling a PyTorch user
would write between pyramid scales, `F.interpolate(x, size=(t, t, t), mode="trilinear",
align_corners=False)` (cell centres, edges clamped: volgen's convention). Timed as
`crates/radiance-volume/examples/resample_step.rs` times volgen's: a `(1, C, S, S, S)` normal
volume, forward alone and forward + backward of `sum(y * p)` for a fixed random `p`, medians of
`--repeat` runs after one warm-up; the same JSON line.

    /tmp/peer/venv/bin/python benches/resample_peer.py --from 89 --to 126 --channels 4 --threads 2
"""
import argparse
import json
import statistics
import time

import torch
import torch.nn.functional as F


def median_seconds(repeat, step):
    step()
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        step()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--from", dest="size_from", type=int, default=89)
    parser.add_argument("--to", type=int, default=126)
    parser.add_argument("--channels", type=int, default=4)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=10)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    s, t, c = args.size_from, args.to, args.channels
    x = torch.randn(1, c, s, s, s, requires_grad=True)
    probe = torch.rand(1, c, t, t, t)

    def forward():
        with torch.no_grad():
            F.interpolate(x, size=(t, t, t), mode="trilinear", align_corners=False)

    def backward():
        x.grad = None
        y = F.interpolate(x, size=(t, t, t), mode="trilinear", align_corners=False)
        (y * probe).sum().backward()

    print(json.dumps({
        "what": "resample", "from": s, "to": t, "channels": c, "threads": args.threads,
        "dtype": "F32", "forward_seconds": round(median_seconds(args.repeat, forward), 6),
        "backward_seconds": round(median_seconds(args.repeat, backward), 6),
    }))


if __name__ == "__main__":
    main()
