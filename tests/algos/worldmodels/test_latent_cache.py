"""V's encodings cached per replayed window (wmdist/algos/worldmodels/latent_cache.py): a cached
window returns exactly what the encoder gives, only unseen windows reach the encoder, the map
stays within its bound, and M's loss is the same with the cache as without it."""
import numpy as np
import torch

from tests.algos.worldmodels.test_learner import SMALL, SPEC, _batch
from wmdist.algos.worldmodels import WorldModels, WorldModelsConfig
from wmdist.algos.worldmodels.latent_cache import LatentCache, window_key


class CountingEncoder:
    """A fixed random linear map of the frames, counting the frames it is given."""

    def __init__(self, z_dim: int = 3) -> None:
        self.w = torch.randn(64 * 64 * 3, 2 * z_dim, generator=torch.Generator().manual_seed(0))
        self.frames = 0

    def __call__(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:  # [N, 64, 64, 3]
        self.frames += len(frames)
        return (frames.flatten(1).float() / 255 @ self.w).chunk(2, -1)


def test_cached_windows_equal_fresh_encodings_and_only_new_windows_are_encoded():
    rng = np.random.default_rng(0)
    windows = rng.integers(0, 255, (4, 5, 64, 64, 3), dtype=np.uint8)  # [W, T, 64, 64, C]
    windows.setflags(write=False)  # as replay hands them out
    enc, cache = CountingEncoder(), LatentCache(max_windows=10)
    mu, logvar = cache.encode(windows[[0, 1]], enc, torch.device("cpu"))
    assert enc.frames == 10 and (cache.hits, cache.misses) == (0, 2)
    mu2, logvar2 = cache.encode(windows[[1, 2, 0, 2]], enc, torch.device("cpu"))  # 1 and 0 known, 2 twice new
    assert enc.frames == 10 + 2 * 5 and cache.hits == 2
    want_mu, want_lv = enc(torch.as_tensor(np.array(windows[[1, 2, 0, 2]])).flatten(0, 1))
    # (to float rounding: the encoder saw other batch sizes)
    torch.testing.assert_close(mu2, want_mu.unflatten(0, (4, 5)), rtol=1e-5, atol=1e-3)
    torch.testing.assert_close(logvar2, want_lv.unflatten(0, (4, 5)), rtol=1e-5, atol=1e-3)
    torch.testing.assert_close(mu2[2], mu[0])


def test_a_changed_frame_misses_and_the_map_keeps_its_bound():
    rng = np.random.default_rng(1)
    w = rng.integers(0, 255, (1, 3, 64, 64, 3), dtype=np.uint8)
    other = w.copy()
    other[0, 2, 10, 10, 0] ^= 1  # one pixel of the last frame
    assert window_key(w[0]) != window_key(other[0])
    assert window_key(w[0]) != window_key(w[0, :2])  # a shorter window of the same frames
    enc, cache = CountingEncoder(), LatentCache(max_windows=2)
    for i in range(5):
        cache.encode(rng.integers(0, 255, (1, 3, 64, 64, 3), dtype=np.uint8), enc, torch.device("cpu"))
        assert len(cache) == min(i + 1, 2)
    cache.encode(w, enc, torch.device("cpu"))
    cache.encode(other, enc, torch.device("cpu"))
    assert cache.misses == 7 and cache.hits == 0


def test_m_trains_the_same_with_the_cache_as_without():
    runs = []
    for cached in (0, 8):
        learner = WorldModels(SPEC, WorldModelsConfig(**{**SMALL, "latent_cache": cached})).make_learner()
        metrics = [learner.update(_batch(i % 2)).metrics for i in range(4)]  # V, V, M, M (the M batch repeats)
        runs.append([m["loss"] for m in metrics[2:]])
        if cached:
            assert metrics[3]["rnn_cache_hit_rate"] == 0.0  # batch 0 then batch 1: both new
            learner.update(_batch(0))  # stage 3 now: the batch is not read
    np.testing.assert_allclose(runs[0], runs[1], rtol=1e-5)
    assert "rnn_done_p_death" in metrics[2] and 0 <= metrics[2]["rnn_done_p_alive"] <= 1
