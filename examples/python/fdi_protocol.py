"""The fdi-mas external-role protocol in Python (docs/protocol.md is the contract).

What a program taking the attacker, the monitor or the controller role of a run needs: the wire types
(ctypes copies of the #[repr(C)] structs of common/runtime/src/ipc/msg.rs, same type names),
the run's environment (FDI_*), the run's iceoryx2 node and services (opened, never created)
and the handshake with the launcher:

    with fdi_protocol.Run("monitor") as run:
        tampered = run.subscriber("fdi/tampered", fdi_protocol.MeasurementMsg)
        ...                                   # the role's other ports
        run.ready_and_wait_for_start()        # READY, then wait for START
        while ...:
            run.wait()                        # timed wait on the role's wake event
            for m in run.drain(tampered): ...
        run.done_and_wait_for_stop()          # DONE, then wait for STOP

A STOP from the launcher, at any time, ends the `with` block (the ports are closed; the
program then exits 0). `python3 fdi_protocol.py --self-check` prints each structure's size,
alignment and field offsets as JSON.
"""

import ctypes
import json
import os
import signal
import sys
import time

import iceoryx2 as iox

MAX_DOF = 12
GAP = 1  # flags bit 0 of MeasurementMsg and TorqueMsg: a gap marker, no data
START, STOP = 1, 2  # ControlMsg.command
READY, PROGRESS, DONE, LOST, REJOINED = 1, 2, 3, 4, 5  # StatusMsg.kind
ROLE_AGENT, ROLE_ATTACKER, ROLE_CENTER, ROLE_MONITOR, ROLE_EXTERNAL_ATTACKER = 1, 2, 3, 4, 5
ROLE_EXTERNAL_CONTROLLER = 6
MISSING, REJECTED = 1, 2  # ControllerInMsg.flags: y, yd are the last good measurement
ALARM, OWN_ALARM = 1, 2  # ControllerOutMsg.flags: its alarm is on; it has an alarm of its own

# Per role: its StatusMsg.role code, its node name, the wake event it waits on.
ROLES = {
    "attacker": (ROLE_EXTERNAL_ATTACKER, "external-attacker", "fdi/wake/external/attacker"),
    "monitor": (ROLE_MONITOR, "monitor", "fdi/wake/monitor"),
    "controller": (ROLE_EXTERNAL_CONTROLLER, "external-controller",
                   "fdi/wake/external/controller"),
}
WAIT_S = 0.05  # one timed wait on the wake event

u32, u64, f64 = ctypes.c_uint32, ctypes.c_uint64, ctypes.c_double
Joints = f64 * MAX_DOF  # only the first `dof` entries are meaningful, the rest 0
# A matrix: MAX_DOF x MAX_DOF, row-major (entry (i, j) at i * MAX_DOF + j); only the first `dof`
# rows and columns are meaningful, the rest 0.
Matrix = f64 * (MAX_DOF * MAX_DOF)


class MeasurementMsg(ctypes.Structure):
    """A measurement: tick `seq`, stamp `t` (s), position `y` (rad), velocity `yd` (rad/s)."""

    _fields_ = [
        ("seq", u64), ("agent", u32), ("dof", u32), ("t", f64), ("y", Joints), ("yd", Joints),
        ("agent_sent_ns", u64), ("attacker_received_ns", u64), ("attacker_sent_ns", u64),
        ("flags", u32), ("reserved", u32),
    ]

    @classmethod
    def type_name(cls):
        return "fdi_mas::MeasurementMsg"


class TorqueMsg(ctypes.Structure):
    """A torque command `u` (N·m) for tick `seq`, stamped `t_send` (s)."""

    _fields_ = [
        ("seq", u64), ("agent", u32), ("dof", u32), ("t_send", f64), ("u", Joints),
        ("agent_sent_ns", u64), ("attacker_received_ns", u64), ("attacker_sent_ns", u64),
        ("center_received_ns", u64), ("center_sent_ns", u64), ("held_s", f64),
        ("flags", u32), ("reserved", u32),
    ]

    @classmethod
    def type_name(cls):
        return "fdi_mas::TorqueMsg"


class ControlMsg(ctypes.Structure):
    """Launcher → every process: START or STOP; `epoch_ns`: CLOCK_MONOTONIC of sim time 0."""

    _fields_ = [("command", u32), ("reserved", u32), ("epoch_ns", u64)]

    @classmethod
    def type_name(cls):
        return "fdi_mas::ControlMsg"


class StatusMsg(ctypes.Structure):
    """Process → launcher: READY, PROGRESS, DONE (and the center's LOST, REJOINED)."""

    _fields_ = [("role", u32), ("agent", u32), ("kind", u32), ("reserved", u32), ("tick", u64)]

    @classmethod
    def type_name(cls):
        return "fdi_mas::StatusMsg"


class AlarmMsg(ctypes.Structure):
    """A monitor's verdict on tick `seq` of `agent`: alarm 1/0, its statistic (NaN if none)."""

    _fields_ = [
        ("seq", u64), ("agent", u32), ("alarm", u32), ("statistic", f64),
        ("monitor_sent_ns", u64),
    ]

    @classmethod
    def type_name(cls):
        return "fdi_mas::AlarmMsg"


class ControllerInMsg(ctypes.Structure):
    """What the control center shows the controller program of tick `seq` of `agent`: the
    measurement in use (y, yd), the reference (q_d, qd_d, qdd_d), e_u, the delay tau(t), and the
    model's terms M(q_d), M(q_d)^-1, M(y), V(y, yd) yd + G(y) + F(yd)."""

    _fields_ = [
        ("seq", u64), ("agent", u32), ("dof", u32), ("t", f64), ("tau", f64),
        ("y", Joints), ("yd", Joints), ("q_d", Joints), ("qd_d", Joints), ("qdd_d", Joints),
        ("e_u", Joints), ("inertia_ref", Matrix), ("inverse_inertia_ref", Matrix),
        ("inertia", Matrix), ("bias", Joints), ("center_sent_ns", u64),
        ("flags", u32), ("reserved", u32),
    ]

    @classmethod
    def type_name(cls):
        return "fdi_mas::ControllerInMsg"


class ControllerOutMsg(ctypes.Structure):
    """The controller program's answer to tick `seq` of `agent`: the torque `u` (N·m), its
    attack estimate `s_hat` (0 without one), its own alarm in `flags` (ALARM | OWN_ALARM)."""

    _fields_ = [
        ("seq", u64), ("agent", u32), ("dof", u32), ("u", Joints), ("s_hat", Joints),
        ("controller_sent_ns", u64), ("flags", u32), ("reserved", u32),
    ]

    @classmethod
    def type_name(cls):
        return "fdi_mas::ControllerOutMsg"


MESSAGES = [
    MeasurementMsg, TorqueMsg, ControlMsg, StatusMsg, AlarmMsg, ControllerInMsg,
    ControllerOutMsg,
]


def monotonic_ns():
    """CLOCK_MONOTONIC, ns (the clock of the *_ns fields and of ControlMsg.epoch_ns)."""
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


class Env:
    """The run's parameters, from the environment the launcher gives the program."""

    def __init__(self, environ=os.environ):
        def get(name):
            if name not in environ:
                sys.exit(f"{name} is not set: this program is started by fdi-launch "
                         "for a scenario's [roles] (docs/protocol.md)")
            return environ[name]

        self.prefix = get("FDI_PREFIX")  # iceoryx2 global prefix of the run
        self.role = get("FDI_ROLE")  # "attacker", "monitor" or "controller"
        self.scenario = get("FDI_SCENARIO")  # the run's resolved scenario (TOML)
        self.run_dir = get("FDI_RUN_DIR")
        self.agents = [int(a) for a in get("FDI_AGENTS").split(",") if a]
        # Joints per agent: one count for every robot, or None for a team of different robots
        # (FDI_DOF is then "mixed"; only a controller program takes such a team).
        dof = get("FDI_DOF")
        self.dof = None if dof == "mixed" else int(dof)
        # Each agent's joints, in the order of FDI_AGENTS.
        self.joints = dict(zip(self.agents, (int(n) for n in get("FDI_JOINTS").split(","))))
        self.ticks = int(get("FDI_TICKS"))  # ticks k = 0 .. ticks - 1
        self.dt = float(get("FDI_CONTROL_PERIOD_S"))  # Δ, the very f64 of the scenario
        self.clock = get("FDI_CLOCK")  # "lockstep" or "realtime"
        self.monitor_lag = int(get("FDI_MONITOR_LAG"))
        self.launcher_pid = int(get("FDI_LAUNCHER_PID"))

    def tick_time(self, k):
        """t_k = k · Δ, as the run computes it (common/src/engine.rs)."""
        return k * self.dt


def launcher_alive(pid):
    """Whether the launcher still runs (a program whose launcher died exits, as the run's
    processes do)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


class Stopped(Exception):
    """The launcher sent STOP."""


class Run:
    """The program's node in the run, its ports, and the handshake with the launcher."""

    def __init__(self, role):
        if role not in ROLES:
            raise ValueError(f"role must be one of {sorted(ROLES)}")
        self.env = Env()
        if self.env.role != role:
            sys.exit(f"this program takes the {role} role, the launcher started it as "
                     f"FDI_ROLE={self.env.role}")
        self.role_code, node_name, wake = ROLES[role]
        self.started, self.epoch_ns = False, 0
        self._held = []  # services and ports, closed in reverse order
        # SIGTERM and SIGINT unwind the `with` block too, so the ports are closed.
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda number, _: sys.exit(128 + number))
        # iceoryx2 logs from Error up, as the run's own processes do
        # (common/runtime/src/ipc/iceoryx.rs): its warnings are about its own fallbacks, e.g.
        # "No config file was loaded" while the program passes its config itself, and would be
        # taken for the program's lines. IOX2_LOG_LEVEL (iceoryx2's variable) asks for more.
        iox.set_log_level_from_env_or(iox.LogLevel.Error)
        # The run's node: service type ipc, iceoryx2's default config with the run's prefix
        # (runs never see each other's services).
        config = iox.config.default()
        config.global_cfg.prefix = iox.FileName.new(self.env.prefix)
        self.node = (iox.NodeBuilder.new().name(iox.NodeName.new(node_name)).config(config)
                     .signal_handling_mode(iox.SignalHandlingMode.Disabled)
                     .create(iox.ServiceType.Ipc))
        try:
            self.control = self.subscriber("fdi/control", ControlMsg)
            self.status = self.publisher("fdi/status", StatusMsg)
            self.launcher = self.notifier("fdi/wake/launcher")
            self.listener = self._keep(self._event(wake).listener_builder().create())
        except BaseException:
            self.close()
            raise

    # Ports. The run created every service before starting the program: only open them.

    def _keep(self, obj):
        self._held.append(obj)
        return obj

    def _open(self, name, builder):
        try:
            return self._keep(builder.open())
        except Exception as e:  # DoesNotExist: not this run; IncompatibleTypes: wrong layout
            raise SystemExit(f"cannot open the service {name} of the run {self.env.prefix}: "
                             f"{e!r}") from None

    def _pubsub(self, name, msg_type):
        builder = self.node.service_builder(iox.ServiceName.new(name))
        # The payload's type name, size and alignment must be the run's (user header: none).
        return self._open(name, builder.publish_subscribe(msg_type))

    def _event(self, name):
        return self._open(name, self.node.service_builder(iox.ServiceName.new(name)).event())

    def subscriber(self, name, msg_type):
        return self._keep(self._pubsub(name, msg_type).subscriber_builder().create())

    def publisher(self, name, msg_type):
        return self._keep(self._pubsub(name, msg_type).publisher_builder().create())

    def notifier(self, name):
        return self._keep(self._event(name).notifier_builder().create())

    def drain(self, subscriber, msg_type=MeasurementMsg):
        """Every waiting message, oldest first, as copies."""
        out = []
        while True:
            sample = subscriber.receive()
            if sample is None:
                return out
            out.append(msg_type.from_buffer_copy(sample.payload().contents))
            sample.delete()

    # The handshake.

    def check_control(self):
        """Reads fdi/control: remembers START (`started`, `epoch_ns`), raises Stopped on STOP."""
        for c in self.drain(self.control, ControlMsg):
            if c.command == STOP:
                raise Stopped()
            if c.command == START:
                self.started, self.epoch_ns = True, c.epoch_ns

    def wait(self, timeout_s=WAIT_S):
        """Blocks until the role's wake event is notified or `timeout_s` passes; then reads
        fdi/control (a STOP raises Stopped). True when it was notified."""
        try:
            rung = bool(self.listener.timed_wait(iox.Duration.from_secs_f64(timeout_s)))
        except iox.ListenerWaitError:  # interrupted by a signal
            rung = False
        self.check_control()
        if not rung and not launcher_alive(self.env.launcher_pid):
            sys.exit("the launcher is gone")
        return rung

    def report(self, kind, tick=0):
        self.status.send_copy(StatusMsg(role=self.role_code, agent=0, kind=kind, tick=tick))
        self.launcher.notify()

    def ready_and_wait_for_start(self):
        """READY, then wait (timed waits) for START; returns its epoch_ns."""
        self.report(READY)
        self.check_control()
        while not self.started:
            self.wait()
        return self.epoch_ns

    def done_and_wait_for_stop(self):
        """DONE (tick = FDI_TICKS), then wait for STOP (which raises Stopped)."""
        self.report(DONE, self.env.ticks)
        while True:
            self.wait()

    def close(self):
        for obj in reversed(self._held):
            if hasattr(obj, "delete"):
                obj.delete()
        self._held.clear()
        self.__dict__.pop("node", None)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close()
        return exc_type is Stopped  # STOP: leave the block normally, the program exits 0


def self_check():
    """Size, alignment, type name and field offsets of every wire structure, as JSON."""
    return {
        cls.__name__: {
            "type_name": cls.type_name(),
            "size": ctypes.sizeof(cls),
            "align": ctypes.alignment(cls),
            "fields": {name: getattr(cls, name).offset for name, _ in cls._fields_},
        }
        for cls in MESSAGES
    }


if __name__ == "__main__":
    if sys.argv[1:] == ["--self-check"]:
        print(json.dumps(self_check(), indent=2))
    else:
        sys.exit(f"usage: {sys.argv[0]} --self-check (this file is a library, see its docstring)")
