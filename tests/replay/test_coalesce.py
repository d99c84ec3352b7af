"""Coalescer (on a fake clock): counts are summed, the first goes at once, later ones with the
first add after `every`, flush sends what is pending, and no thread is ever started."""
from __future__ import annotations

import threading

from wmdist.replay.coalesce import Coalescer


def test_counts_are_summed_sent_on_the_callers_thread_and_flushed():
    got, t = [], [0.0]
    threads = threading.active_count()
    c = Coalescer(lambda n, steps: got.append((n, steps, threading.get_ident())), 2, every=0.05,
                  clock=lambda: t[0])
    c.add(1, 10)
    assert [g[:2] for g in got] == [(1, 10)]  # the first at once
    for i in range(50):  # within the interval: held, not one call per add
        t[0] = 0.0009 * i
        c.add(2, 20)
    assert len(got) == 1 and c.pending == (100, 1000)
    t[0] = 0.06  # the interval is over: the next add sends everything held
    c.add(3, 30)
    assert [g[:2] for g in got] == [(1, 10), (103, 1030)] and c.pending == (0, 0)
    t[0] = 0.07
    c.add(4, 40)
    assert len(got) == 2  # held again
    c.flush()  # before a read of the counts: sent whatever the clock says
    assert got[-1][:2] == (4, 40)
    c.flush()  # nothing pending: nothing sent
    assert len(got) == 3 and sum(g[0] for g in got) == 108 and sum(g[1] for g in got) == 1080
    assert {g[2] for g in got} == {threading.get_ident()} and threading.active_count() == threads


def test_adds_from_several_threads_lose_nothing():
    got = []
    c = Coalescer(lambda n: got.append(n), 1, every=0.001)

    def work() -> None:
        for _ in range(2000):
            c.add(1)

    ts = [threading.Thread(target=work) for _ in range(4)]
    for th in ts:
        th.start()
    for th in ts:
        th.join()
    c.flush()
    assert sum(got) == 8000


def test_the_first_send_and_a_settling_flush_wait_for_what_was_sent():
    """The receiver may run calls out of order: the first count and `flush(settle=True)` (before
    the counts are read back) wait for every send not waited for yet, and only those."""
    sent, waited, t = [], [], [0.0]

    def send(n):
        sent.append(n)
        return f"h{len(sent)}"

    c = Coalescer(send, 1, every=0.05, clock=lambda: t[0], wait=lambda hs: waited.append(list(hs)))
    c.add(1)
    assert sent == [1] and waited == [["h1"]]  # a fresh sender's first count is applied on return
    for i in range(1, 4):  # later sends are not waited for
        t[0] = 0.1 * i
        c.add(1)
    assert sent == [1, 1, 1, 1] and waited == [["h1"]]
    c.add(5)  # held
    c.flush(settle=True)
    assert sent[-1] == 5 and waited[-1] == ["h2", "h3", "h4", "h5"]
    c.flush(settle=True)  # nothing sent since: nothing to wait for
    assert len(waited) == 2
