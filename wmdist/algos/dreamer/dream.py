"""The open-loop video moved to `wmdist.algos.dream_video` (shared with PlaNet); this name stays for old imports."""
from wmdist.algos.dream_video import open_loop_video, predict_open_loop

__all__ = ["open_loop_video", "predict_open_loop"]
