"""DirectChannel: a CyclicChannel straight onto a SlaveModel, on a simulated clock.

For unit tests of codecs and sim models without the bus in between (the bus-level tests go through
sim:// and dp/). Each exchange advances the simulated clock by `period` seconds.
"""

from __future__ import annotations

from profidrive_cli.sim.model import SlaveModel


class DirectChannel:
    def __init__(self, model: SlaveModel, layout_cfg: bytes, period: float = 0.01, start: float = 0.0):
        if not model.check_cfg(layout_cfg):
            raise ValueError(f"model refuses cfg {layout_cfg.hex(' ')}")
        self.model = model
        self.period = period
        self._now = start
        self.cycles = 0

    def now(self) -> float:
        return self._now

    def exchange(self, outputs: bytes) -> bytes:
        if len(outputs) != self.model.output_len:
            raise ValueError(f"outputs are {len(outputs)} octets, configuration says {self.model.output_len}")
        self._now += self.period
        self.cycles += 1
        self.model.tick(self._now)
        inputs = self.model.data_exchange(bytes(outputs), self._now)
        assert len(inputs) == self.model.input_len, "model returned wrong input length"
        return inputs

    def advance(self, seconds: float) -> None:
        """Let time pass without traffic (e.g. to trigger a comm-loss reaction)."""
        self._now += seconds
        self.model.tick(self._now)
