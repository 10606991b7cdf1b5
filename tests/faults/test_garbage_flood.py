"""A garbage flood on a real pty against a slave: memory stays bounded, the slave does
not spin once the flood is over, and it answers a good request right after."""

from __future__ import annotations

import random

from .flood import garbage_flood

SEED = 15


async def test_a_garbage_flood_leaves_the_slave_bounded_idle_and_answering() -> None:
    result = await garbage_flood(random.Random(SEED), 400_000, idle=0.5)
    print(result)
    assert result.answered, f"seed {SEED}: no right answer after the flood"
    assert result.discarded > 1000, result  # the garbage did reach the slave
    # Receive buffers are bounded (a frame is at most 256 bytes): 400 kB of garbage
    # must not stay in memory. 8 MB leaves room for the allocator's own growth.
    assert result.rss_growth < 8 * 1024 * 1024, result
    # A loop that spins after the flood uses all the CPU it gets (0.5 s in 0.5 s on an
    # idle machine); an idle one sleeps in epoll. 0.2 s catches any spin that gets 40 %
    # of a core, with room for noise.
    assert result.idle_cpu < 0.2, result
