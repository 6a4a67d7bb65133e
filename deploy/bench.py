"""``frontiernet bench inference``: network speed per runtime, as ratios to eager torch.

Times one forward pass at each size (median of repeats, batch 1, random input of the
model's channels) for: torch eager with torch's default threads (the baseline), torch with
2 and 1 threads, the library's Predictor (channels-last layout; default threads, and 1),
TorchScript, and onnxruntime (default threads, and 2). Also the training
throughput (forward + backward + AdamW step, images/s) at the training crop.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

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


def _training_throughput(model, channels: int, crop: int, batch: int, conf, inference_fps: float) -> dict:
    """Images/s of a training step on this machine's device (GPU when there is one)."""
    import torch

    from frontiernet.benchmark.perf import median_seconds

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

    seconds = median_seconds(step, repeats=3, warmup=1)
    model.eval().cpu()
    return {"device": torch.cuda.get_device_name(0) if device.type == "cuda" else "cpu", "crop": crop, "batch": batch,
            "images_per_s": round(batch / seconds, 1),
            "ratio_to_inference_fps": round(batch / seconds / inference_fps, 3)}


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("inference", help="network speed: torch, TorchScript, onnxruntime; training "
                                                     "images/s")
    parser.add_argument("--model", default=None, help="model file (default: the shipped model)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[320, 480], help="square input sizes")
    parser.add_argument("--repeats", type=int, default=10, help="timed repetitions (median is reported)")
    parser.add_argument("--json", action="store_true", help="print JSON only")
    parser.set_defaults(func=run)


def run(args) -> int:
    from frontiernet.errors import InputError

    if args.repeats < 1 or min(args.sizes) < 8:
        raise InputError("--repeats must be >= 1 and --sizes >= 8")
    from importlib.metadata import entry_points

    exports = {entry.name for entry in entry_points(group="frontiernet.runtimes")}  # onnx, pt, ...: exported files
    if args.model is not None and Path(args.model).suffix.lower().lstrip(".") in exports:
        raise InputError(f"{args.model}: bench inference times a torch model against its own ONNX and TorchScript "
                         "exports, so it needs the model file (.safetensors) or a training checkpoint (.ckpt), "
                         "not an export")
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
