"""``frontiernet bench train``: does the training loader keep ahead of the model?

In one run, on one machine: the loader's samples/s (training batches delivered to the training
loop: crop, flip and jitter factors in the workers, per-pixel augmentation and normalisation on
the device) at each worker count, for the training cache and for decoding the dataset on every
read (``data.cache: null``, the baseline, ~28 ms a view on one core; with 0 workers also the CPU
milliseconds a sample costs, a figure that a busy machine barely moves), then the model's training
images/s (forward, the training loss, backward, AdamW) on the same device at the same batch and
crop, and the ratio loader / model. The loader keeps ahead when that ratio is >= 1.
"""

from __future__ import annotations

import json
import time

from frontiernet.cli import options

# torch and lightning are imported where they are used: `frontiernet` loads this module to list
# `bench train` with every command it parses.


def _loader_rate(samples, conf, workers: int, batches: int, device) -> dict:
    """Samples/s of a shuffled training DataLoader over `samples`, batches moved to `device` and
    made network batches there, timed over `batches` batches after every worker's first one."""
    import torch
    from torch.utils.data import DataLoader

    from .data import _one_thread
    from .transforms import network_batch

    batch_size = int(conf.data.batch_size)
    loader = DataLoader(samples, batch_size=batch_size, shuffle=True, num_workers=workers, drop_last=True,
                        pin_memory=device.type == "cuda", worker_init_fn=_one_thread,
                        generator=torch.Generator().manual_seed(0))
    warmup = max(1, workers)
    if (warmup + batches) * batch_size > len(samples):
        batches = max(1, len(samples) // batch_size - warmup)
    model_conf, augment_conf = conf.model, conf.augment
    torch.manual_seed(0)
    iterator = iter(loader)
    for _ in range(warmup):
        network_batch({k: v.to(device, non_blocking=True) for k, v in next(iterator).items()}, model_conf, augment_conf)
    _synchronise(device)
    start, cpu_start = time.perf_counter(), time.process_time()
    for _ in range(batches):
        network_batch({k: v.to(device, non_blocking=True) for k, v in next(iterator).items()}, model_conf, augment_conf)
    _synchronise(device)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu_start
    del iterator
    row = {"workers": workers, "batches": batches, "samples_per_s": round(batches * batch_size / seconds, 1)}
    if workers == 0:  # all the work in this process: its CPU time per sample, steady on a busy machine
        row["cpu_ms_per_sample"] = round(1000 * cpu_seconds / (batches * batch_size), 2)
    return row


def _synchronise(device) -> None:
    import torch

    if device.type == "cuda":
        torch.cuda.synchronize()


def _model_rate(samples, conf, device, steps: int, precision: str, channels_last: bool = False) -> dict:
    """Training images/s of FrontierNet with the training loss on `device` (median step time), with
    the network in NCHW or NHWC (`channels_last`) memory order."""
    import numpy as np
    import torch
    from torch.utils.data import DataLoader

    from .config import plain
    from .module import FrontierNetModule
    from .transforms import network_batch

    module = FrontierNetModule(model=plain(conf.model), train={key: plain(conf[key]) for key in ("loss", "optim")})
    module = module.to(device).train()
    module.use_channels_last(channels_last)
    optimizer = torch.optim.AdamW(module.parameters(), lr=float(conf.optim.lr))
    loader = DataLoader(samples, batch_size=int(conf.data.batch_size), shuffle=True, drop_last=True,
                        generator=torch.Generator().manual_seed(0))
    batch = network_batch({k: v.to(device) for k, v in next(iter(loader)).items()}, conf.model, conf.augment)
    autocast = precision.startswith("bf16") or precision.startswith("16")
    dtype = torch.bfloat16 if precision.startswith("bf16") else torch.float16

    def step():
        optimizer.zero_grad(set_to_none=True)
        with torch.autocast(device.type, dtype=dtype, enabled=autocast):
            terms, _, _ = module._loss(batch)
        terms["loss"].backward()
        optimizer.step()
        _synchronise(device)

    times = []
    for index in range(steps + 2):
        start = time.perf_counter()
        step()
        if index >= 2:  # two warm-up steps (allocator, cuDNN autotuning)
            times.append(time.perf_counter() - start)
    seconds = float(np.median(times))
    size = batch["image"].shape
    return {"device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
            "precision": precision, "encoder": conf.model.network.encoder, "inputs": conf.model.network.inputs,
            "channels_last": channels_last, "batch": int(size[0]), "crop": int(size[-1]), "steps": steps,
            "step_ms": round(1000 * seconds, 1), "images_per_s": round(int(size[0]) / seconds, 1)}


def bench_train(conf, workers: list[int], batches: int, steps: int, baseline: bool = True,
                precision: str | None = None) -> dict:
    """Loader samples/s per source and worker count, model images/s, and their ratio (module doc)."""
    import torch

    from .data import CachedSamples, TrainingSamples, open_training_cache, open_training_data, view_size
    from .main import channels_last_wanted

    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    precision = precision or ("bf16-mixed" if device.type == "cuda" else "32-true")
    dataset = open_training_data(conf.data.path)
    if len(dataset) < int(conf.data.batch_size):
        from frontiernet.errors import InputError

        raise InputError(f"{conf.data.path}: {len(dataset)} views, fewer than one batch (data.batch_size "
                         f"{conf.data.batch_size}); give a smaller data.batch_size or a larger dataset")
    started = time.perf_counter()
    cache = open_training_cache(conf.data, conf.model, dataset, progress=False)
    cache_seconds = time.perf_counter() - started
    indices = list(range(len(cache)))
    seed = int(conf.seed)
    cached = CachedSamples(cache, indices, conf.augment, seed)
    decoded = TrainingSamples(dataset, conf.model, int(conf.data.image_size or view_size(dataset)), conf.augment, seed)
    result = {"data": str(conf.data.path), "views": len(cache), "cache": str(cache.path),
              "cache_open_or_build_s": round(cache_seconds, 2), "device": str(device), "batch": int(conf.data.batch_size),
              "crop": conf.augment.crop_size, "loader": []}
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # on a CPU the batch transform runs in this process: one core's cost, no thread spin
    try:
        for count in workers:
            if baseline:
                result["loader"].append({"source": "decode", **_loader_rate(decoded, conf, count, batches, device)})
            result["loader"].append({"source": "cache", **_loader_rate(cached, conf, count, batches, device)})
    finally:
        torch.set_num_threads(threads)
    rows = result["loader"]
    base = next((row for row in rows if row["source"] == "decode"), rows[0])["samples_per_s"]
    for row in rows:
        row["ratio_to_baseline"] = round(row["samples_per_s"] / base, 2)
    result["baseline"] = f"{'decode' if baseline else 'cache'}, {rows[0]['workers']} worker(s)"
    layouts = [_model_rate(cached, conf, device, steps, precision, channels_last) for channels_last in (False, True)]
    for layout in layouts:
        layout["ratio_to_nchw"] = round(layout["images_per_s"] / layouts[0]["images_per_s"], 2)
    result["model_layouts"] = layouts
    result["model"] = layouts[int(channels_last_wanted(conf.trainer))]  # the layout `train` would use
    best = max(row["samples_per_s"] for row in rows if row["source"] == "cache")
    result["loader_to_model"] = round(best / result["model"]["images_per_s"], 2)
    return result


def format_report(result: dict) -> str:
    lines = [f"training data {result['data']}: {result['views']} views; cache {result['cache']} "
             f"(opened or built in {result['cache_open_or_build_s']} s)",
             f"loader, batch {result['batch']}, crop {result['crop']} px, delivered to {result['device']} "
             f"(augmented and normalised there):"]
    for row in result["loader"]:
        source = "cache" if row["source"] == "cache" else "decode every read (data.cache: null)"
        cpu = f"  ({row['cpu_ms_per_sample']} ms CPU a sample)" if "cpu_ms_per_sample" in row else ""
        lines.append(f"  {source:38s} {row['workers']:2d} worker(s)  {row['samples_per_s']:9.1f} samples/s  "
                     f"{row['ratio_to_baseline']:6.2f}x{cpu}")
    model = result["model"]
    lines.append(f"model training step ({model['encoder']}, {model['inputs']}, batch {model['batch']}, "
                 f"{model['crop']} px, {model['precision']}, {model['device']}):")
    for layout in result["model_layouts"]:
        name = "channels-last (NHWC)" if layout["channels_last"] else "contiguous (NCHW)"
        used = "  <- trainer.channels_last" if layout is model else ""
        lines.append(f"  {name:22s} {layout['step_ms']:8.1f} ms  {layout['images_per_s']:9.1f} images/s  "
                     f"{layout['ratio_to_nchw']:5.2f}x{used}")
    lines.append(f"best cache loader / model: {result['loader_to_model']}x "
                 f"({'the loader keeps ahead' if result['loader_to_model'] >= 1 else 'the model waits for data'})")
    return "\n".join(lines)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("train", help="training loader samples/s vs the model's training images/s",
                                   description=__doc__.split("\n\n")[0])
    options.config_file(parser, "configs/train.yaml (as `frontiernet train`)")
    options.config_overrides(parser, "data.path=DIR data.batch_size=64 (data.path is required)")
    parser.add_argument("--workers", type=int, nargs="+", metavar="W",
                        help="distinct loader worker counts to time (default: 0, 1 and the machine's cores)")
    parser.add_argument("--batches", type=int, default=20, help="batches timed per loader (default 20)")
    parser.add_argument("--steps", type=int, default=5, help="model training steps timed (median; default 5)")
    parser.add_argument("--precision", help="model precision: 32-true, bf16-mixed or 16-mixed "
                                            "(default: bf16-mixed on a GPU, else 32-true)")
    parser.add_argument("--no-baseline", action="store_true", help="skip the decode-every-read loader")
    options.json_only(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    import os

    from frontiernet.cli.bench import COUNT_LIMITS
    from frontiernet.errors import InputError, cpu_count_option, whole_number

    from .config import load_train_config

    conf = load_train_config(args.config, args.overrides)
    workers = args.workers or sorted({0, 1, min(os.cpu_count() or 1, 16)})
    for count in workers:
        cpu_count_option(count, "--workers", 0)
    if len(set(workers)) != len(workers):  # (the same loader timed twice)
        raise InputError(f"--workers must list distinct worker counts, got {' '.join(map(str, workers))}")
    whole_number(args.batches, "--batches", 1, COUNT_LIMITS["repeats"])  # timed repetitions (1e8 ran until killed)
    whole_number(args.steps, "--steps", 1, COUNT_LIMITS["repeats"])
    if args.precision not in (None, "32-true", "bf16-mixed", "16-mixed"):
        raise InputError(f"--precision: expected 32-true, bf16-mixed or 16-mixed, got {args.precision!r}")
    result = bench_train(conf, workers, args.batches, args.steps, not args.no_baseline, args.precision)
    print(json.dumps(result, indent=2) if args.json else format_report(result))
    return 0
