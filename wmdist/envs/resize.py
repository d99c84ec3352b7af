"""Square resizing of RGB frames for the pixel families that render at another size
(CarRacing 96x96, ViZDoom 160x120 -> the project's 64x64 convention)."""
from __future__ import annotations

import numpy as np
from PIL import Image


def resize_square(frame: np.ndarray, side: int) -> np.ndarray:
    """uint8 [H, W, 3] -> uint8 [side, side, 3], area-averaged (no aliasing when shrinking)."""
    if frame.shape[0] == side and frame.shape[1] == side:
        return np.ascontiguousarray(frame, dtype=np.uint8)
    img = Image.fromarray(np.ascontiguousarray(frame, dtype=np.uint8))
    return np.asarray(img.resize((side, side), Image.Resampling.BOX), dtype=np.uint8)
