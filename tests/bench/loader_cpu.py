"""CPU milliseconds a training sample costs in `frontiernet train`'s loader, for any checkout.

Builds the checkout's own ``FrontierDataModule`` on a dataset and times (``time.process_time``, one
thread, one process: a figure a busy machine barely moves) `BATCHES` training batches, plus the
device-side batch transform where the checkout has one (``train.transforms.network_batch``). Point
it at a worktree of an older commit to compare loaders across versions:

    git worktree add /tmp/old 565c730   # the loader before the training cache
    .venv/bin/python tests/bench/loader_cpu.py /tmp/old DATASET 10
    .venv/bin/python tests/bench/loader_cpu.py . DATASET 10
"""

from __future__ import annotations

import sys
import time


def main(repo: str, dataset: str, batches: int) -> None:
    sys.path.insert(0, repo)
    import torch

    from train.config import load_train_config
    from train.data import FrontierDataModule

    torch.set_num_threads(1)
    conf = load_train_config(None, [f"data.path={dataset}", "data.num_workers=0", "data.max_val_samples=8"])
    module = FrontierDataModule(conf)
    module.setup()
    try:
        from train.transforms import network_batch

        def transform(batch):
            return network_batch(batch, conf.model, conf.augment)
    except ImportError:  # older checkouts augment and normalise in the loader itself
        def transform(batch):
            return batch
    torch.manual_seed(0)
    iterator = iter(module.train_dataloader())
    transform(next(iterator))  # the cache is built (or opened) and warm
    start = time.process_time()
    for _ in range(batches):
        transform(next(iterator))
    samples = batches * int(conf.data.batch_size)
    print(f"{repo}: {1000 * (time.process_time() - start) / samples:.2f} ms CPU a sample ({samples} samples)")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
