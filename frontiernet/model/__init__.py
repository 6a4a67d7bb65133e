"""The FrontierNet network and its model files (:mod:`.network`), the prediction recipe with its input and
output encoding and the runtimes (:mod:`.predictor`), and the overlay pictures (:mod:`.overlay`)."""

from .network import (ENCODERS, FEATURE_ENCODERS, INPUT_CHANNELS, SHIPPED_MODELS, FrontierNet, NetworkConfig,
                      default_model_path, load_imagenet_encoder, load_model, save_model, shipped_model_path)
from .predictor import (Predictor, Runtime, check_images, decode_distance, encode_distance, invalid_to_zero,
                        network_input, normalise_batch, normalise_images, open_runtime, resize_and_crop)

__all__ = ["ENCODERS", "FEATURE_ENCODERS", "INPUT_CHANNELS", "FrontierNet", "NetworkConfig", "Predictor", "Runtime",
           "check_images",
           "SHIPPED_MODELS", "decode_distance", "default_model_path", "shipped_model_path", "encode_distance", "invalid_to_zero",
           "load_imagenet_encoder", "load_model", "network_input", "normalise_batch", "normalise_images", "open_runtime", "resize_and_crop",
           "save_model"]
