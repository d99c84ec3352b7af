"""WindowRates: per-second rates over a trailing window, checked against a plain recount."""
import pytest

from wmdist.runtime.rates import WindowRates


def _reference(samples: list[tuple[float, float]], now: float, window: float) -> float:
    """The newest sample at least `window` old (else the first) is the base: a plain scan."""
    base_t, base_v = samples[0]
    for t, v in samples:
        if now - t >= window:
            base_t, base_v = t, v
    cur = samples[-1][1]
    return (cur - base_v) / (now - base_t)


def test_chunked_arrivals_read_as_a_steady_rate_not_zero():
    # a collector delivers 400 env steps every 20 s; the driver samples every 2 s
    window = 30.0
    r = WindowRates(window, 0.0, {"env_steps": 0})
    steps, samples, seen = 0, [(0.0, 0.0)], []
    for i in range(1, 151):
        now = 2.0 * i
        if i % 10 == 0:
            steps += 400
        samples.append((now, float(steps)))
        got = r.update(now, {"env_steps": steps})["env_steps"]
        assert got == pytest.approx(_reference(samples, now, window))
        if now >= 60:
            seen.append(got)
    # the true rate is 20/s; a two-sample rate would read 0 on 9 ticks of 10
    assert min(seen) > 10 and max(seen) < 30
    assert sum(seen) / len(seen) == pytest.approx(20.0, rel=0.15)


def test_rates_start_from_the_first_sample_and_handle_several_counters():
    r = WindowRates(10.0, 100.0, {"a": 5, "b": 0})
    got = r.update(104.0, {"a": 13, "b": 2})
    assert got == {"a": pytest.approx(2.0), "b": pytest.approx(0.5)}
    assert r.update(104.0, {"a": 13, "b": 2}) == {"a": pytest.approx(2.0), "b": pytest.approx(0.5)}


def test_zero_span_and_bad_window():
    r = WindowRates(5.0, 1.0, {"a": 0})
    assert r.update(1.0, {"a": 3}) == {"a": 0.0}
    with pytest.raises(ValueError):
        WindowRates(0.0, 0.0, {})
