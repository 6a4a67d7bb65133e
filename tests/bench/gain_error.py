"""How far the gain a model's outputs decode to lies from the label's, on the pixels the planner reads
(issue 26 item 4, issue 27 step 4; docs/model.md "Gain-loss comparison").

On the ground-truth frontier pixels of labelled gain (class > 0) that the pipeline keeps (the model's
most likely class > 0, as ``anchoring.drop_zero_gain`` keeps them), prints |log(decoded / label)|
(both in m^3; the label decoded to its bin's midpoint) for each way of decoding the model's gain
classes: ``argmax`` (the most likely class's midpoint, ``gain_decoding: midpoint``), ``expected``
(sum_k p_k midpoint_k, ``gain_decoding: expected``) and ``expected_gain_classes`` (the same over
classes 1-10 renormalised, geometric).

    .venv/bin/python tests/bench/gain_error.py --data DATASET [--model FILE] [--every 3]
"""
import argparse

import numpy as np
import torch
from scipy.special import softmax
from torch.utils.data import DataLoader

from frontiernet.frontiers.gain import class_midpoints, decode_gain
from frontiernet.model import load_model
from train.data import TrainingSamples, open_training_data
from train.transforms import network_batch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="a frontiernet datagen dataset (every scene is read)")
    parser.add_argument("--model", default=None, help="model file (default: the shipped one)")
    parser.add_argument("--every", type=int, default=3, help="read every N-th view (default 3)")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    model, conf = load_model(args.model)
    dataset = open_training_data(args.data)
    samples = TrainingSamples(dataset.subset(list(range(0, len(dataset), args.every))), conf,
                              int(conf["inference"]["size"]))
    edges, unit = conf["labels"]["bin_edges"], float(conf["labels"]["bin_unit_m3"])
    midpoints = class_midpoints(edges, unit)
    errors, kept, total = {"argmax": [], "expected": [], "expected_gain_classes": []}, 0, 0
    with torch.inference_mode():
        for batch in DataLoader(samples, batch_size=4):
            batch = network_batch(batch, conf)
            logits = np.moveaxis(model(batch["image"])[1].float().numpy(), 1, 0)  # (K, B, H, W)
            classes = logits.argmax(0)  # the most likely class, as the runtimes give it
            target = batch["gain_class"].numpy()
            read = batch["frontier"].numpy().astype(bool) & (target > 0)
            keep = read & (classes > 0)
            total, kept = total + int(read.sum()), kept + int(keep.sum())
            label = midpoints[target[keep]]
            p = softmax(logits[:, keep], axis=0)[1:]  # (K - 1, N) gain classes
            decoded = {"argmax": decode_gain(classes, edges, unit, "midpoint")[keep],  # the library's decodings
                       "expected": decode_gain(classes, edges, unit, "expected", logits, keep)[keep],
                       "expected_gain_classes": np.exp(np.log(midpoints[1:]) @ (p / p.sum(0)))}
            for name, gain in decoded.items():
                errors[name].append(np.abs(np.log(gain / label)))
    print(f"{kept} of {total} labelled frontier pixels kept (the model's most likely class > 0)")
    for name, values in errors.items():
        values = np.concatenate(values)
        print(f"{name:>22}: mean |log(decoded / label)| {values.mean():.3f}, median {np.median(values):.3f}, "
              f"within 2x {np.mean(values < np.log(2)):.3f}")


if __name__ == "__main__":
    main()
