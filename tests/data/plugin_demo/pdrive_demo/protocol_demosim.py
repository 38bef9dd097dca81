"""demosim://: a port kind from a plug-in (pyserial's protocol_<scheme> convention): the simulated bus
of sim:// under another name."""

from profidrive_cli.sim.protocol_sim import Serial as _SimSerial


class Serial(_SimSerial):
    def open(self):
        self._port = "sim://" + str(self._port).split("://", 1)[1]
        super().open()
