"""Station view: the devices (a station file or the built-in mock bench), a check that they
answer, the channel table (sensitivity, range, IEPE, node, direction editable) and live
levels with overloads per channel."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from PySide6 import QtCore, QtWidgets

from app.acquire.plan import TestPlan
from app.gui.streaming import DeviceSource, StreamThread
from app.gui.views.levels import LevelsWidget
from app.gui.widgets import fill_table
from app.gui.worker import TaskRunner
from app.mockbench import bench_names, unavailable
from app.report.analysis import message_of
from drivers.base import AcquisitionFrontEnd, ChannelConfig
from drivers.errors import DeviceError
from drivers.registry import create_device
from drivers.station import DeviceConfig, StationConfig, load_station

if TYPE_CHECKING:
    from app.mockbench.bench import InProcessBench

__all__ = ["StationView"]

_CHANNEL_COLUMNS = ("device", "channel", "input", "quantity", "unit", "sensitivity (mV/unit)",
                    "range (±V)", "IEPE", "node", "direction (x y z)")
_EDITABLE = {5, 6, 7, 8, 9}
_MOCK = "mock:"
#: the mock bench's built-in shaker plan: periodic chirp, 1 s blocks (1 Hz lines), 2 averages
MOCK_SHAKER = {"waveform": "chirp", "level": 0.5, "f_start": 2.0, "f_stop": 400.0,
               "averages": 2, "nperseg": 1024, "ramp": 0.1, "settle": 1.0}


class StationView(QtWidgets.QWidget):
    """Choose and check the station; watch live levels.

    Signals
    -------
    station_changed(object)
        The new :class:`StationConfig` (or None).
    plan_offered(object)
        A plan that goes with the station (the mock bench's built-in plan).
    message(str, str)
        (level, text) for the message bar.
    """

    station_changed = QtCore.Signal(object)
    plan_offered = QtCore.Signal(object)
    message = QtCore.Signal(str, str)

    def __init__(self, settings: QtCore.QSettings, runner: TaskRunner,
                 station: Path | None = None, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.settings = settings
        self.runner = runner
        runner.done.connect(self._checked)
        self.station: StationConfig | None = None
        self.source = ""
        self.mock: InProcessBench | None = None
        self.stream: StreamThread | None = None
        self.bench_combo = QtWidgets.QComboBox()
        #: why the mock bench cannot run on this system ("" when it can: POSIX)
        self.mock_unavailable = unavailable()
        self.bench_combo.addItems(bench_names())
        self.bench_combo.setCurrentText("engine-rigid")
        self.method_combo = QtWidgets.QComboBox()
        self.method_combo.addItems(["hammer", "shaker"])
        self.method_combo.setToolTip("The built-in plan offered with the mock bench: impact "
                                     "hammer, or shaker (periodic chirp)")
        self.method_combo.setCurrentText(str(settings.value("mock_method", "hammer", str)))
        self.mock_button = QtWidgets.QPushButton("Use mock bench")
        self.mock_button.setToolTip("Simulated front end and hammer on the chosen bench, with "
                                    "a simulated operator who hits where the plan asks")
        self.open_button = QtWidgets.QPushButton("Open station file…")
        self.check_button = QtWidgets.QPushButton("Check devices")
        self.monitor_button = QtWidgets.QPushButton("Start live levels")
        self.monitor_button.setCheckable(True)
        self.tap_button = QtWidgets.QPushButton("Simulated hit")
        self.tap_button.setToolTip("Mock bench only: hit the bench once at the first "
                                   "excitation point, to see the levels move")
        if self.mock_unavailable:  # offered only where it runs
            for w in (self.mock_button, self.bench_combo, self.method_combo):
                w.setEnabled(False)
                w.setToolTip(self.mock_unavailable)
        self.mock_button.clicked.connect(lambda: self.use_mock(self.bench_combo.currentText()))
        self.open_button.clicked.connect(self._open_dialog)
        self.check_button.clicked.connect(self.check_devices)
        self.monitor_button.toggled.connect(self._toggle_monitor)
        self.tap_button.clicked.connect(self._tap)
        top = QtWidgets.QHBoxLayout()
        top.addWidget(QtWidgets.QLabel("Built-in bench:"))
        top.addWidget(self.bench_combo)
        top.addWidget(QtWidgets.QLabel("plan:"))
        top.addWidget(self.method_combo)
        top.addWidget(self.mock_button)
        top.addSpacing(16)
        top.addWidget(self.open_button)
        top.addStretch(1)
        top.addWidget(self.check_button)
        top.addWidget(self.monitor_button)
        top.addWidget(self.tap_button)
        self.name_label = QtWidgets.QLabel(
            "No station: open a station file" if self.mock_unavailable else
            "No station: use the mock bench or open a station file")
        self.devices = QtWidgets.QTableWidget()
        self.devices.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.channels = QtWidgets.QTableWidget()
        self.channels.itemChanged.connect(self._channel_edited)
        self.levels = LevelsWidget()
        left = QtWidgets.QWidget()
        ll = QtWidgets.QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        ll.addWidget(self.name_label)
        ll.addWidget(QtWidgets.QLabel("Devices:"))
        ll.addWidget(self.devices, 1)
        ll.addWidget(QtWidgets.QLabel("Channels (double-click to edit sensitivity, range, IEPE, "
                                      "node, direction):"))
        ll.addWidget(self.channels, 3)
        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        split.addWidget(left)
        split.addWidget(self.levels)
        split.setSizes([640, 600])
        lay = QtWidgets.QVBoxLayout(self)
        lay.addLayout(top)
        lay.addWidget(split, 1)
        self._filling = False
        self._status: dict[str, str] = {}
        self._update_buttons()
        self._initial = station

    def start(self) -> None:
        """Load the station given on the command line, else the last one, else the mock."""
        last = str(self.settings.value("last_station", "", str))
        if self._initial is not None:
            self.load_file(self._initial)
        elif (last.startswith(_MOCK) and last[len(_MOCK):] in bench_names()
              and not self.mock_unavailable):
            self.use_mock(last[len(_MOCK):])
        elif last and Path(last).is_file():
            self.load_file(Path(last))

    # --- choosing the station ----------------------------------------------------------------
    def use_mock(self, name: str, shakers: int = 1, offer_plan: bool = True) -> None:
        """Start the in-process mock bench ``name`` with ``shakers`` shakers and use its
        station, and its plan when ``offer_plan`` (a message instead where it cannot run)."""
        if self.mock_unavailable:
            self.message.emit("error", self.mock_unavailable)
            return
        from app.mockbench.bench import InProcessBench

        self._close_mock()
        self.mock = InProcessBench(name, operator={"pause": 0.05}, shakers=shakers)
        self.bench_combo.setCurrentText(name)
        self._set_station(self.mock.station, f"{_MOCK}{name}")
        if offer_plan:
            self.plan_offered.emit(self.mock_plan())

    def mock_plan(self, points: list[int] | None = None) -> TestPlan | None:
        """The mock bench's built-in plan, hammer or shaker as chosen (None without a mock
        bench)."""
        if self.mock is None:
            return None
        from app.mockbench.bench import plan_for_bench

        method = self.method_combo.currentText()
        return plan_for_bench(self.mock.bench.name, points=points, length=1.0, method=method,
                              shaker=MOCK_SHAKER if method == "shaker" else None)

    def _open_dialog(self) -> None:
        name, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open station file", "",
                                                        "Station (*.toml);;All files (*)")
        if name:
            self.load_file(Path(name))

    def load_file(self, path: Path) -> bool:
        """Use the station file ``path``; False (with a message) when it is invalid."""
        try:
            station = load_station(path)
        except (ValueError, OSError) as err:
            self.message.emit("error", f"cannot use the station file: {message_of(err)}")
            return False
        self._close_mock()
        self._set_station(station, str(path))
        return True

    def _set_station(self, station: StationConfig, source: str) -> None:
        self.stop_monitor()
        self.station, self.source = station, source
        self._status = {}
        self.name_label.setText(f"Station: {station.name} ({'simulated' if self.mock else source})")
        self._fill()
        self._update_buttons()
        self.station_changed.emit(station)

    def _fill(self) -> None:
        st = self.station
        if st is None:
            return
        fill_table(self.devices, ("device", "backend", "transport", "fs (Hz)", "status"), [
            (d.name, d.backend, _transport(d), f"{d.fs:g}" if d.fs else "default",
             self._status.get(d.name, "not checked")) for d in st.devices.values()])
        self._filling = True
        try:
            rows = [(d.name, c) for d in st.devices.values() for c in d.channels]
            fill_table(self.channels, _CHANNEL_COLUMNS, [
                (dev, c.name, str(c.input), c.quantity, c.unit, f"{c.sensitivity:g}",
                 f"{c.range_v:g}", "yes" if c.iepe else "no",
                 "" if c.node is None else str(c.node),
                 "" if c.direction is None else " ".join(f"{v:.4g}" for v in c.direction))
                for dev, c in rows])
            for i in range(self.channels.rowCount()):
                for j in _EDITABLE:
                    item = self.channels.item(i, j)
                    if item is not None:
                        item.setFlags(item.flags() | QtCore.Qt.ItemFlag.ItemIsEditable)
        finally:
            self._filling = False

    def _channel_edited(self, item: QtWidgets.QTableWidgetItem) -> None:
        if self._filling or self.station is None:
            return
        i = item.row()
        cells = [_cell(self.channels.item(i, j)) for j in range(len(_CHANNEL_COLUMNS))]
        dev_name, ch_name = cells[0], cells[1]
        dev = self.station.devices[dev_name]
        old = next(c for c in dev.channels if c.name == ch_name)
        try:
            new = _edited_channel(old, cells)
        except ValueError as err:
            self.message.emit("error", f"channel {ch_name}: {message_of(err)}")
            self._fill()
            return
        chans = tuple(new if c.name == ch_name else c for c in dev.channels)
        devices = {**self.station.devices, dev_name: replace(dev, channels=chans)}
        self.station = replace(self.station, devices=devices)
        self.station_changed.emit(self.station)

    # --- checking and monitoring -----------------------------------------------------------------
    def check_devices(self) -> None:
        """Open and close every device once, in the background; the status column says
        what answered."""
        if self.station is None:
            return
        self.stop_monitor()
        station = self.station
        for name in station.devices:
            self._status[name] = "checking…"
        self._fill()
        self.runner.submit("station.check", lambda: _check_all(station))

    @QtCore.Slot(str, object)
    def _checked(self, key: str, status: object) -> None:
        if key != "station.check" or not isinstance(status, dict):
            return
        self._status = dict(status)
        self._fill()
        bad = [n for n, s in self._status.items() if s != "OK"]
        self.message.emit("error" if bad else "info",
                          f"devices not answering: {', '.join(bad)}" if bad
                          else "every device answered")

    def _toggle_monitor(self, on: bool) -> None:
        if on:
            self.start_monitor()
        else:
            self.stop_monitor()

    def start_monitor(self) -> bool:
        """Stream every acquisition device to the level meters (off the GUI thread)."""
        if self.station is None or self.stream is not None:
            return False
        try:
            devs = [create_device(d) for d in self.station.devices.values()]
        except (DeviceError, OSError, ValueError) as err:
            self.message.emit("error", f"cannot start live levels: {message_of(err)}")
            self.monitor_button.setChecked(False)
            return False
        fronts = [d for d in devs if isinstance(d, AcquisitionFrontEnd)]
        self.stream = StreamThread(DeviceSource(fronts), self)
        self.stream.failed.connect(self._stream_failed)
        self.levels.attach(self.stream)
        self.stream.start()
        self.monitor_button.setChecked(True)
        self.monitor_button.setText("Stop live levels")
        return True

    def stop_monitor(self) -> None:
        """Stop the live levels (devices released); idempotent."""
        if self.stream is not None:
            self.levels.detach()
            self.stream.stop()
            self.stream = None
        self.monitor_button.blockSignals(True)
        self.monitor_button.setChecked(False)
        self.monitor_button.blockSignals(False)
        self.monitor_button.setText("Start live levels")

    def _stream_failed(self, text: str) -> None:
        self.stop_monitor()
        self.message.emit("error", f"live levels stopped: {text}")

    def _tap(self) -> None:
        if self.mock is not None:
            self.mock.hammer.hit(exc=0, delay=0.05)

    def _update_buttons(self) -> None:
        has = self.station is not None
        self.check_button.setEnabled(has)
        self.monitor_button.setEnabled(has)
        self.tap_button.setEnabled(self.mock is not None)

    # --- life cycle ------------------------------------------------------------------------------
    def _close_mock(self) -> None:
        self.stop_monitor()
        if self.mock is not None:
            self.mock.shutdown()
            self.mock = None

    def save_settings(self) -> None:
        if self.source:
            self.settings.setValue("last_station", self.source)
        self.settings.setValue("mock_method", self.method_combo.currentText())

    def shutdown(self) -> None:
        """Stop streaming and the mock bench (window closing)."""
        self._close_mock()


def _check_all(station: StationConfig) -> dict[str, str]:
    """Open and shut down each device (worker thread): name -> "OK" or why not."""
    out: dict[str, str] = {}
    for d in station.devices.values():
        try:
            with create_device(d):
                pass
        except (DeviceError, OSError, ValueError) as err:
            out[d.name] = f"NOT answering: {message_of(err)}"
        else:
            out[d.name] = "OK"
    return out


def _transport(d: DeviceConfig) -> str:
    t = d.transport
    url = getattr(t, "url", None)
    return url or f"CAN {getattr(t, 'interface', '')} {getattr(t, 'channel', '')}"


def _edited_channel(old: ChannelConfig, cells: list[str]) -> ChannelConfig:
    """The channel with the table's editable cells applied; ValueError names the bad cell."""
    try:
        sens, rng = float(cells[5]), float(cells[6])
    except ValueError:
        raise ValueError("sensitivity and range must be numbers") from None
    iepe = cells[7].strip().lower()
    if iepe not in ("yes", "no", "true", "false", "1", "0"):
        raise ValueError("IEPE must be yes or no")
    node_text = cells[8].strip()
    node = int(node_text) if node_text else None
    d_text = cells[9].replace(",", " ").split()
    direction = tuple(float(v) for v in d_text) if d_text else None
    if direction is not None and (len(direction) != 3 or not any(direction)):
        raise ValueError("direction must be three numbers, not all zero")
    return ChannelConfig(old.name, old.input, old.quantity, sens,  # validated there
                         iepe in ("yes", "true", "1"), rng, node, direction)


def _cell(item: QtWidgets.QTableWidgetItem | None) -> str:
    return item.text() if item is not None else ""
