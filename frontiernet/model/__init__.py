"""The FrontierNet network, its input/output encoding, model files and the torch runtime."""

from .checkpoint import SHIPPED_MODELS, default_model_path, load_model, save_model, shipped_model_path
from .network import ENCODERS, FEATURE_ENCODERS, INPUT_CHANNELS, FrontierNet, NetworkConfig, load_imagenet_encoder
from .predictor import (Predictor, Runtime, check_images, decode_distance, encode_distance, invalid_to_zero,
                        network_input, normalise_batch, normalise_images, open_runtime, resize_and_crop)

__all__ = ["ENCODERS", "FEATURE_ENCODERS", "INPUT_CHANNELS", "FrontierNet", "NetworkConfig", "Predictor", "Runtime",
           "check_images",
           "SHIPPED_MODELS", "decode_distance", "default_model_path", "shipped_model_path", "encode_distance", "invalid_to_zero",
           "load_imagenet_encoder", "load_model", "network_input", "normalise_batch", "normalise_images", "open_runtime", "resize_and_crop",
           "save_model"]
