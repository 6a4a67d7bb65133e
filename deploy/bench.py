"""``frontiernet bench inference``: network speed per runtime, as ratios to eager torch.

Times one forward pass at each size (median of repeats, batch 1, random input of the
model's channels) for: torch eager with torch's default threads (the baseline), torch with
2 and 1 threads, the library's Predictor (channels-last layout; default threads, and 1),
TorchScript, and onnxruntime (default threads, and 2). Also the training
throughput (forward + backward + AdamW step, images/s) at the training crop.

``--encoders A,B,...`` compares encoders instead (:func:`bench_encoders`): randomly initialised
networks that differ from the model only in ``network.encoder``, timed in turns in the library's
Predictor layout (channels-last; default threads, and 1) and in training, as speed-ups over the
first encoder listed.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from frontiernet.cli import options

# torch (and the benchmark package) are imported where they are used: `frontiernet` loads this
# module to list `bench inference` with every command it parses, and importing torch took seconds
# of each start.


def bench_inference(model_path=None, sizes=(320, 480), repeats: int = 10, train_crop: int = 192,
                    train_batch: int = 8) -> dict:
    import torch

    from frontiernet.benchmark.perf import median_seconds
    from frontiernet.model import load_model
    from frontiernet.model.predictor import Predictor, torch_threads

    from .export import export
    from .runtime import OnnxRuntime, TorchScriptRuntime

    model, conf = load_model(model_path)
    channels = model.config.in_channels
    default_threads = torch.get_num_threads()
    results = {"model": str(model_path or "shipped"), "encoder": model.config.encoder,
               "inputs": model.config.inputs, "torch_threads_default": default_threads, "sizes": {}}
    with tempfile.TemporaryDirectory() as folder:
        onnx_path = export(model_path, "onnx", Path(folder) / "model.onnx")
        script_path = export(model_path, "torchscript", Path(folder) / "model.pt")
        runtimes = {"onnxruntime": OnnxRuntime(onnx_path), "onnxruntime_2_threads": OnnxRuntime(onnx_path, 2)}
        script = TorchScriptRuntime(script_path)
        predictor, predictor_1 = Predictor(model_path), Predictor(model_path, threads=1)
        for size in sizes:
            image = np.random.default_rng(0).standard_normal((1, channels, size, size)).astype(np.float32)
            tensor = torch.from_numpy(image)

            def eager(threads: int):
                def run():
                    with torch_threads(threads), torch.inference_mode():
                        model(tensor)
                return run

            seconds = {"torch_eager": median_seconds(eager(default_threads), repeats),
                       "torch_2_threads": median_seconds(eager(min(2, default_threads)), repeats),
                       "torch_1_thread": median_seconds(eager(1), repeats),
                       # the library's Predictor (explore, predict, demo): channels-last weights and input
                       "predictor_channels_last": median_seconds(lambda: predictor.run(image), repeats),
                       "predictor_channels_last_1_thread": median_seconds(lambda: predictor_1.run(image), repeats)}
            seconds["torchscript"] = median_seconds(lambda: script.run(image), repeats)
            for name, runtime in runtimes.items():
                seconds[name] = median_seconds(lambda runtime=runtime: runtime.run(image), repeats)
            baseline = seconds["torch_eager"]
            results["sizes"][str(size)] = {name: {"ms": round(1000 * value, 1), "fps": round(1.0 / value, 1),
                                                  "ratio_to_torch_eager": round(value / baseline, 3)}
                                           for name, value in seconds.items()}
    results["training"] = _training_throughput(model, channels, train_crop, train_batch, conf,
                                               results["sizes"][str(sizes[0])]["torch_eager"]["fps"])
    return results


def bench_encoders(encoders: list[str], model_path=None, sizes=(320, 480), repeats: int = 10,
                   train_crop: int = 192, train_batch: int = 8) -> dict:
    """Inference ms and training images/s of FrontierNet with each of `encoders` (torchvision names,
    ``frontiernet.model.ENCODERS``), the other network settings those of the model (None: the
    shipped one), random weights; each figure also as the speed-up over ``encoders[0]``."""
    import torch

    from frontiernet.benchmark.perf import median_seconds_interleaved
    from frontiernet.model import FrontierNet, NetworkConfig, load_model
    from frontiernet.model.predictor import torch_threads

    _, conf = load_model(model_path)
    torch.manual_seed(0)
    models = {name: FrontierNet(NetworkConfig.from_dict({**conf["network"], "encoder": name})).eval()
              for name in encoders}
    channels = models[encoders[0]].config.in_channels
    default_threads = torch.get_num_threads()
    results = {"model": str(model_path or "shipped"), "inputs": conf["network"]["inputs"], "baseline": encoders[0],
               "torch_threads_default": default_threads, "layout": "channels-last (the library's Predictor)",
               "parameters_m": {name: round(sum(p.numel() for p in model.parameters()) / 1e6, 2)
                                for name, model in models.items()}, "sizes": {}}
    for model in models.values():
        model.to(memory_format=torch.channels_last)
    for size in sizes:
        tensor = torch.randn(1, channels, size, size).contiguous(memory_format=torch.channels_last)
        rows = {}
        for threads in sorted({default_threads, 1}, reverse=True):
            def forward(model, threads=threads):
                def run():
                    with torch_threads(threads), torch.inference_mode():
                        model(tensor)
                return run
            seconds = median_seconds_interleaved({name: forward(model) for name, model in models.items()}, repeats)
            for name, value in seconds.items():
                rows.setdefault(name, {})[f"ms_{threads}_threads"] = round(1000 * value, 1)
                rows[name][f"speedup_{threads}_threads"] = round(seconds[encoders[0]] / value, 2)
        results["sizes"][str(size)] = rows
    steps = {}
    for model in models.values():
        model.to(memory_format=torch.contiguous_format)
    for name, model in models.items():
        steps[name], device = _training_step(model, channels, train_crop, train_batch, conf)
    training = {"device": torch.cuda.get_device_name(0) if device.type == "cuda" else "cpu", "crop": train_crop,
                "batch": train_batch, "rows": {}}
    for threads in sorted({default_threads, 1} if device.type == "cpu" else {default_threads}, reverse=True):
        def with_threads(step, threads=threads):
            def run():
                with torch_threads(threads):
                    step()
            return run
        seconds = median_seconds_interleaved({name: with_threads(step) for name, step in steps.items()}, repeats=3,
                                             warmup=1)
        for name, value in seconds.items():
            training["rows"].setdefault(name, {})[f"images_per_s_{threads}_threads"] = round(train_batch / value, 2)
            training["rows"][name][f"speedup_{threads}_threads"] = round(seconds[encoders[0]] / value, 2)
    results["training"] = training
    return results


def _training_step(model, channels: int, crop: int, batch: int, conf):
    """A training step (forward, loss, backward, AdamW) of `model`, moved to this machine's device
    (GPU when there is one) and set training, on a random batch; and that device."""
    import torch

    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    model = model.to(device).train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    image = torch.randn(batch, channels, crop, crop, device=device)
    classes = torch.randint(0, int(conf["labels"]["num_classes"]), (batch, crop, crop), device=device)

    def step():
        optimizer.zero_grad()
        distance, logits = model(image)
        loss = distance.mean() + torch.nn.functional.cross_entropy(logits, classes)
        loss.backward()
        optimizer.step()
        if device.type == "cuda":
            torch.cuda.synchronize()

    return step, device


def _training_throughput(model, channels: int, crop: int, batch: int, conf, inference_fps: float) -> dict:
    """Images/s of a training step on this machine's device (GPU when there is one)."""
    import torch

    from frontiernet.benchmark.perf import median_seconds

    step, device = _training_step(model, channels, crop, batch, conf)
    seconds = median_seconds(step, repeats=3, warmup=1)
    model.eval().cpu()
    return {"device": torch.cuda.get_device_name(0) if device.type == "cuda" else "cpu", "crop": crop, "batch": batch,
            "images_per_s": round(batch / seconds, 1),
            "ratio_to_inference_fps": round(batch / seconds / inference_fps, 3)}


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("inference", help="network speed: torch, TorchScript, onnxruntime; training "
                                                     "images/s")
    options.model_option(parser, exports=False)
    parser.add_argument("--sizes", type=int, nargs="+", default=[320, 480], help="square input sizes")
    parser.add_argument("--repeats", type=int, default=10, help="timed repetitions (median is reported)")
    parser.add_argument("--encoders", metavar="A,B,...",
                        help="compare these encoders instead (comma-separated, e.g. resnet18,mobilenet_v3_large,"
                             "efficientnet_b0): random weights, the model's other network settings; speed-ups over "
                             "the first")
    options.json_only(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    from frontiernet.cli.bench import counts
    from frontiernet.errors import InputError
    from frontiernet.model.files import is_export
    from frontiernet.model.predictor import input_size

    counts(repeats=args.repeats)  # (a typo such as 100001 ran until killed)
    for size in args.sizes:
        input_size(size, "--sizes")
    if len(set(args.sizes)) < len(args.sizes):  # (each size is timed once; a repeat only doubled the wait)
        raise InputError(f"--sizes {' '.join(map(str, args.sizes))}: a size given twice; give each once")

    if args.model is not None and is_export(args.model):
        raise InputError(f"{args.model}: bench inference times a torch model against its own ONNX and TorchScript "
                         "exports, so it needs the model file (.safetensors) or a training checkpoint (.ckpt), "
                         "not an export")
    if args.encoders is not None:
        return _run_encoders(args)
    results = bench_inference(args.model, tuple(args.sizes), args.repeats)
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(f"model {results['model']} ({results['encoder']}, {results['inputs']}), torch default threads "
          f"{results['torch_threads_default']}")
    for size, rows in results["sizes"].items():
        print(f"  {size} x {size}")
        for name, row in rows.items():
            print(f"    {name:24s} {row['ms']:8.1f} ms  {row['fps']:6.1f} fps  x{row['ratio_to_torch_eager']:.2f} "
                  f"of torch eager")
    training = results["training"]
    print(f"  training on {training['device']}: {training['images_per_s']} images/s at {training['crop']} px crops, "
          f"batch {training['batch']}")
    return 0


def _run_encoders(args) -> int:
    from frontiernet.errors import InputError
    from frontiernet.model import ENCODERS

    encoders = [name.strip() for name in args.encoders.split(",") if name.strip()]
    unknown = [name for name in encoders if name not in ENCODERS]
    if not encoders or unknown or len(set(encoders)) != len(encoders):
        raise InputError(f"--encoders must list distinct names of {', '.join(ENCODERS)}, got {args.encoders!r}")
    results = bench_encoders(encoders, args.model, tuple(args.sizes), args.repeats)
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    base = results["baseline"]
    print(f"encoders on the network of model {results['model']} ({results['inputs']}), random weights, "
          f"{results['layout']}; speed-up over {base} in the same run (timed in turns)")
    for size, rows in results["sizes"].items():
        print(f"  {size} x {size}, inference")
        for name, row in rows.items():
            print(f"    {name:20s} {results['parameters_m'][name]:6.2f} M params  {_cells(row, 'ms', 'ms')}")
    training = results["training"]
    print(f"  training on {training['device']}, {training['crop']} px crops, batch {training['batch']}")
    for name, row in training["rows"].items():
        print(f"    {name:20s}  {_cells(row, 'images_per_s', 'images/s')}")
    return 0


def _cells(row: dict, key: str, unit: str) -> str:
    """'value unit xSPEEDUP (T thr)' for each thread count T in a bench_encoders row."""
    threads = [name.rsplit("_", 2)[1] for name in row if name.startswith("speedup_")]
    return "  ".join(f"{row[f'{key}_{t}_threads']:8.1f} {unit} x{row[f'speedup_{t}_threads']:.2f} ({t} thr)"
                     for t in threads)
