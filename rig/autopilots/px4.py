"""PX4 SITL as the rig's autopilot: find the user's build, give it the vehicle's airframe,
start it in the run folder, keep its console and its ULog, stop it.

Nothing of PX4 is vendored: the user's own ``build/px4_sitl_default``-shaped folder
(``bin/px4`` + ``etc/``) is found through ``--px4 DIR`` or ``$PX4_DIR``. PX4 runs in a fresh
work dir ``RUN/px4`` (its parameters, dataman and ``log/``), as airframe 10016, PX4's generic
quad X that starts ``simulator_mavlink``, with the rig's parameters on top: the vehicle's
rotors and motor outputs replace the quad's, so a hexa or an octo flies it too.

The rig's parameters reach PX4 after its airframe file, through scripts that ``rcS``
sources from ``PATH`` (:class:`ParameterHook`, read from the build): the rig writes them
into ``RUN/px4/bin`` and puts that folder first in PX4's ``PATH``. The same folder holds the
``px4-<module>`` command links that ``rcS`` calls (a build copied without its symlinks has
plain files there).

Lockstep at any IMU rate, the same rule from v1.14 to v1.17 (their source and binaries,
docs/guide/px4-releases.md): PX4's ``simulator_mavlink`` sends HIL_ACTUATOR_CONTROLS when
``pwm_out_sim`` publishes its outputs, which follows the rate controller, which runs on
``vehicle_angular_velocity`` at most at ``IMU_GYRO_RATEMAX``; before sending it waits for
every lockstep component (the logger, and each work queue with work queued, EKF2's on
``vehicle_imu`` at ``IMU_INTEG_RATE``). So ``IMU_GYRO_RATEMAX`` and ``IMU_INTEG_RATE``
must both equal the simulator's IMU rate, and ``IMU_INTEG_RATE`` stops at 1000 Hz. With
PX4's defaults (400 and 200 Hz) only Gazebo's 250 Hz is answered frame by frame.

PX4 flies on one CPU (:func:`px4_cpu`) when the rig may use two or more. Its modules are
threads that wake each other in a chain every lockstep frame; spread over the cores, each
wake-up crosses cores and PX4 also preempts the rig on its own core. On one core PX4 spent
about half the CPU time and PX4 + rig ran 1.5× faster (``make bench``, 2 cores). It is
held there only once its start-up script has ended (:meth:`Px4Sitl.hold_to_one_cpu`):
as root its threads are SCHED_FIFO, and one that spins at start-up until another thread
of its priority has run (seen in ``sensors start``) starves it for good on one CPU.

A real vehicle's parameters (a replay flies PX4 with the log's own, :func:`sitl_parameters`)
are taken where they describe how the vehicle flies, and never where they describe its
hardware (calibrations, drivers, ports, outputs) or what SITL and the rig need (airframe
10016, lockstep, the sticks as MAVLink MANUAL_CONTROL): :data:`NOT_FROM_THE_VEHICLE`.
"""

from __future__ import annotations

import contextlib
import enum
import json
import lzma
import math
import os
import re
import shlex
import shutil
import subprocess
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from quad_model.vehicle import Vehicle
from rig.errors import RigError
from rig.mavlink.px4_api import mavlink
from rig.processes import exit_description, start_child, stop_process_group

#: The environment variable naming the user's PX4 build (or PX4-Autopilot checkout).
PX4_DIR_ENV = "PX4_DIR"
#: PX4's generic quad X SITL airframe (``etc/init.d-posix/airframes/10016_none_iris``): it
#: starts ``simulator_mavlink`` on TCP 4560+i; the rig's parameters replace its geometry.
AIRFRAME = 10016
#: ``IMU_INTEG_RATE``'s range in PX4 v1.14 (``sensors/vehicle_imu/imu_parameters.c``).
IMU_INTEG_RATE_RANGE_HZ = (100, 1000)
#: PX4's output function Motor 1 (``mixer_module/output_functions.yaml``); Motor n is 100 + n.
MOTOR_OUTPUT_FUNCTION = 101
#: ``MAV_TYPE`` by rotor count, as PX4's quad, hexa and octo airframes set it (the X8 too).
MAV_TYPES = {4: mavlink.MAV_TYPE_QUADROTOR, 6: mavlink.MAV_TYPE_HEXAROTOR,
             8: mavlink.MAV_TYPE_OCTOROTOR}  # fmt: skip
#: Seconds PX4 gets to shut down (close its ULog) after SIGINT before it is killed.
STOP_GRACE_S = 5.0


def px4_cpu() -> int | None:
    """The CPU a PX4 about to start runs on: of the CPUs the rig may use (``taskset``
    narrows them), the one with the fewest PX4 processes already held to it (counted from
    ``/proc``), the last on a tie, so that runs side by side (a campaign, parallel tests)
    spread out instead of sharing one; None when the rig has a single CPU."""
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return None
    taken = Counter(cpus_of_pinned_px4())
    return min(reversed(cpus), key=lambda cpu: taken[cpu])


def cpus_of_pinned_px4() -> Iterator[int]:
    """The CPU of each running PX4 process held to a single CPU."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if (entry / "comm").read_text().strip() != "px4":
                continue
            status = (entry / "status").read_text()
        except OSError:  # ended meanwhile, or not ours to read
            continue
        for line in status.splitlines():
            if line.startswith("Cpus_allowed_list:"):
                allowed = line.split(":", 1)[1].strip()
                if allowed.isdigit():
                    yield int(allowed)


class Px4NotFound(RigError):
    """``--px4``/``$PX4_DIR`` names no PX4 SITL build the rig can fly."""


#: The oldest PX4 release whose simulator API and start-up script the rig knows.
OLDEST_RELEASE = (1, 14)
#: A PX4 checkout's build keeps its version here (``src/lib/version``'s generated header).
_GIT_VERSION_HEADER = Path("src/lib/version/build_git_version.h")
#: PX4's version tag as its build embeds it ("v1.14.0", "v1.17.0-alpha1", "v1.15.2-12-gab12").
_TAG = re.compile(rb"\bv(\d+)\.(\d+)\.(\d+)[0-9A-Za-z.+\-]*")


class ParameterHook(enum.Enum):
    """Where a build's start-up script (``etc/init.d-posix/rcS``) lets the rig set
    parameters after the airframe's, which changed between releases (PX4 commit 9e8b530,
    v1.16, dropped ``px4-rc.params``).

    v1.16's own way, ``PX4_PARAM_<NAME>`` environment variables, is applied *before* the
    airframe: a value equal to PX4's built-in default is then not kept as set, and the
    airframe's ``param set-default`` replaces it (``IMU_GYRO_RATEMAX 400`` became 800
    through ``rc.mc_defaults``, and lockstep at 400 Hz stalled). So the rig does not use it.
    """

    #: v1.14, v1.15: ``rcS`` sources ``px4-rc.params`` from ``PATH`` after the airframe.
    RC_PARAMS_FILE = "px4-rc.params"
    #: v1.16 on: ``rcS`` sources ``px4-rc.simulator`` from ``PATH`` after the airframe; the
    #: rig's own runs the build's, then sets the parameters.
    SIMULATOR_SCRIPT = "px4-rc.simulator"


@dataclass(frozen=True)
class Px4Build:
    """A ``build/px4_sitl_default``-shaped folder: ``bin/px4`` and ``etc/init.d-posix/rcS``,
    with the release it was built from and the way its ``rcS`` takes parameters."""

    root: Path
    #: PX4's version tag ("v1.17.0-alpha1"); "unknown" when the build does not carry one.
    tag: str
    release: tuple[int, int] | None
    hook: ParameterHook

    @property
    def binary(self) -> Path:
        return self.root / "bin" / "px4"

    @property
    def etc(self) -> Path:
        return self.root / "etc"

    @property
    def description(self) -> str:
        """What a run's summary says of the build it flew."""
        return f"PX4 {self.tag} ({self.root}; parameters through {self.hook.value})"


def find_px4(explicit: Path | None = None) -> Px4Build | None:
    """The build named by ``explicit`` (``--px4``), else by ``$PX4_DIR``, else None (the user
    starts PX4 by hand). A PX4-Autopilot checkout is accepted for its
    ``build/px4_sitl_default``. A folder that holds no PX4, or a PX4 older than
    :data:`OLDEST_RELEASE`, fails in one line."""
    given = explicit if explicit is not None else os.environ.get(PX4_DIR_ENV) or None
    if given is None:
        return None
    source = "--px4" if explicit is not None else f"${PX4_DIR_ENV}"
    folder = Path(given).expanduser()
    for root in (folder, folder / "build" / "px4_sitl_default"):
        root = root.resolve()
        binary, rcs = root / "bin" / "px4", root / "etc" / "init.d-posix" / "rcS"
        if os.access(binary, os.X_OK) and rcs.is_file():
            return _read_build(root, rcs, f"{source} = {given}")
    raise Px4NotFound(
        f"{source} = {given}: no PX4 SITL build there (expected bin/px4 and "
        "etc/init.d-posix/rcS, or build/px4_sitl_default/ holding them; build one with "
        "`make px4_sitl` in PX4-Autopilot)"
    )


def _read_build(root: Path, rcs: Path, named: str) -> Px4Build:
    tag, release = _release(root)
    oldest = "v{}.{}".format(*OLDEST_RELEASE)
    if release is not None and release < OLDEST_RELEASE:
        raise Px4NotFound(f"{named}: PX4 {tag} is older than {oldest}, the oldest release the "
                          "rig flies (its simulator API and start-up script differ)")  # fmt: skip
    script = rcs.read_text(errors="replace")
    if "px4-rc.params" in script:
        hook = ParameterHook.RC_PARAMS_FILE
    elif re.search(r"^\s*\. px4-rc\.simulator\s*$", script, re.MULTILINE):
        hook = ParameterHook.SIMULATOR_SCRIPT
    else:
        raise Px4NotFound(
            f"{named}: {rcs} sources neither px4-rc.params nor px4-rc.simulator, so "
            f"the rig cannot give this PX4 ({tag}) its parameters; is it a PX4 SITL build of "
            f"{oldest} or later?"
        )
    return Px4Build(root, tag, release, hook)


def _release(root: Path) -> tuple[str, tuple[int, int] | None]:
    """PX4's version tag and (major, minor): from a checkout build's generated version
    header, else from the tag the binary carries. Every build also holds the made-up tags
    of PX4's versioning self-test (v1.2.3, v1.8.2-beta4, v11.45.99-1.2.3, v255.255.255-11):
    only a v1.10..v9.x tag is taken for the build's own."""
    header = root / _GIT_VERSION_HEADER
    if header.is_file():
        text = header.read_bytes()
        anchor = text.find(b"PX4_GIT_TAG_STR")
        found = _TAG.search(text, anchor) if anchor >= 0 else None
        candidates = [found] if found else []
    else:
        candidates = list(_TAG.finditer((root / "bin" / "px4").read_bytes()))
    for match in candidates:
        release = (int(match.group(1)), int(match.group(2)))
        if (1, 10) <= release < (10, 0):
            return match.group(0).decode(), release
    return "unknown", None


def check_imu_rate(imu_hz: int, build: Px4Build | None = None) -> None:
    """Refuse, before the run, an IMU rate at which PX4 cannot keep lockstep: one outside
    the range the build's ``IMU_INTEG_RATE`` takes (v1.14-v1.17: 100..1000 Hz)."""
    low, high = IMU_INTEG_RATE_RANGE_HZ
    if build is not None:
        spec = build_parameters(build).get("IMU_INTEG_RATE")
        if spec is not None and spec.low is not None and spec.high is not None:
            low, high = int(spec.low), int(spec.high)
    if not low <= imu_hz <= high:
        nearest = min(max(imu_hz, low), high)
        release = "PX4 v1.14-v1.17" if build is None else f"PX4 {build.tag}"
        raise RigError(
            f"rates.imu_hz = {imu_hz}: PX4 answers every lockstep frame only when "
            f"IMU_INTEG_RATE equals the IMU rate, and {release} allows {low}..{high} Hz; "
            f"the nearest rate that works is {nearest} Hz"
        )


def lockstep_parameters(imu_hz: int) -> dict[str, float]:
    """PX4's rate controller and EKF2 run once per simulated IMU sample (see module doc)."""
    check_imu_rate(imu_hz)
    return {"IMU_GYRO_RATEMAX": imu_hz, "IMU_INTEG_RATE": imu_hz}


#: A NAV-PVT frame (8 bytes of framing, 92 of payload, 10 bits a byte) on the UART at the
#: 115 200 Bd PX4's u-blox driver sets: what a fix waits after the receiver sends it (ms).
NAV_PVT_TRANSFER_MS = (8 + 92) * 10 / 115_200 * 1e3


def airframe_parameters(vehicle: Vehicle, hover_throttle: float) -> dict[str, float]:
    """What a PX4 airframe file for ``vehicle`` sets, as PX4's Gazebo airframes do for the
    x500: rotor geometry (``CA_ROTORi_PX/PY/PZ/KM``, PX4 motor order, KM the torque/thrust
    ratio, + for CCW; a coaxial pair's lower rotor as PX4's coaxial airframes have it, the
    same KM magnitude and thrust coefficient as the upper), motor ``i`` on output ``i``
    (``PWM_MAIN_FUNCi+1`` = Motor ``i+1``: airframe 10016 maps the first four, and PX4
    SITL's HIL_ACTUATOR_CONTROLS carries output ``i`` as its ``controls[i]``), the hover
    thrust, the vehicle type (``MAV_TYPE``) and the battery cells; and, as a real vehicle's
    configuration does, the GPS's delay (``EKF2_GPS_DELAY``: the receiver's latency and
    the NAV-PVT's transfer). PX4 SITL's start-up sets that delay to 10 ms from v1.16 on
    (Gazebo's GPS has none); trusting a 119 ms old fix as 10 ms old, v1.17's estimate
    trailed a 5 m step by 0.48 m and the vehicle overshot it by 1.07 m.

    PX4 normalizes its allocation matrix, so KM's sign and the rotors' relative positions
    shape the mixer, not KM's magnitude. ``hover_throttle`` is the model's ESC throttle at
    hover, which is PX4's normalized motor output when the rig's PWM range maps 0..1 onto
    the ESC's whole range.
    """
    propulsion = vehicle.propulsion
    ratio = propulsion.torque_coefficient_nm_per_radps2 / propulsion.thrust_coefficient_n_per_radps2
    params: dict[str, float] = {"CA_AIRFRAME": 0, "CA_ROTOR_COUNT": propulsion.rotor_count}
    for i, ((x, y, z), spin) in enumerate(
        zip(propulsion.position_frd_m, propulsion.spin_direction, strict=True)
    ):
        params |= {f"CA_ROTOR{i}_PX": x, f"CA_ROTOR{i}_PY": y, f"CA_ROTOR{i}_PZ": z,
                   f"CA_ROTOR{i}_KM": spin * ratio,
                   f"PWM_MAIN_FUNC{i + 1}": MOTOR_OUTPUT_FUNCTION + i}  # fmt: skip
    params["MAV_TYPE"] = MAV_TYPES[propulsion.rotor_count]
    params["MPC_THR_HOVER"] = round(float(hover_throttle), 3)
    params["BAT1_N_CELLS"] = vehicle.battery.cell_count
    params["EKF2_GPS_DELAY"] = round(vehicle.gps.latency_s * 1e3 + NAV_PVT_TRANSFER_MS, 1)
    return params


def sensor_parameters(vehicle: Vehicle, *, gps: bool, optical_flow: bool) -> dict[str, float]:
    """What a vehicle's configuration says of the sensors it flies with, beyond PX4's
    defaults (a receiver, no flow): without GPS, none expected (``SYS_HAS_GPS``) nor fused
    (``EKF2_GPS_CTRL``); with an optical-flow camera, flow fused (``EKF2_OF_CTRL``), its
    mount (``EKF2_OF_POS_X/Y/Z``, body FRD from the model's reference point, where the
    IMU is) and no rotation (``SENS_FLOW_ROT``: the rig's chip is mounted as PX4's default
    expects); without GPS the height reference is the barometer (``EKF2_HGT_REF`` 0), and a
    rangefinder aids it near the ground (PX4's default ``EKF2_RNG_CTRL``). Not the
    rangefinder as reference: EKF2 then estimates no terrain, and from v1.17 on it starts
    flow fusion only with a terrain estimate or another horizontal aid, so flow never starts.
    """
    params: dict[str, float] = {}
    if not gps:
        params |= {"SYS_HAS_GPS": 0, "EKF2_GPS_CTRL": 0, "EKF2_HGT_REF": 0}
    if optical_flow:
        assert vehicle.optical_flow is not None, "the scenario's check: the vehicle has a camera"
        x, y, z = vehicle.optical_flow.position_frd_m
        params |= {"EKF2_OF_CTRL": 1, "SENS_FLOW_ROT": 0, "EKF2_OF_POS_X": x,
                   "EKF2_OF_POS_Y": y, "EKF2_OF_POS_Z": z}  # fmt: skip
    return params


#: Always set: no HITL (lockstep SITL), PX4's own simulated sensors off (the rig's chips
#: are the sensors), and PX4's ULog from boot to shutdown so it covers the whole run.
RIG_PARAMETERS: dict[str, float] = {
    "SYS_HITL": 0,
    "SENS_EN_GPSSIM": 0,
    "SENS_EN_BAROSIM": 0,
    "SENS_EN_MAGSIM": 0,
    "SDLOG_MODE": 2,
}


def px4_parameters(vehicle: Vehicle, hover_throttle: float, imu_hz: int,
                   explicit: tuple[str, ...], build: Px4Build | None,
                   sensors: Mapping[str, float] | None = None,
                   ) -> tuple[dict[str, float], tuple[str, ...]]:  # fmt: skip
    """Everything the rig sets in PX4: its own needs, lockstep, the vehicle's airframe, the
    sensors it flies with (:func:`sensor_parameters`), and then the user's
    ``--param NAME=VALUE`` texts, which win name by name.

    With the build known, the rig's own names the build lacks are left out and returned,
    so PX4 never prints a "not found" for them; a ``--param`` the build lacks fails in one
    line.
    """
    airframe = airframe_parameters(vehicle, hover_throttle)
    own = RIG_PARAMETERS | lockstep_parameters(imu_hz) | airframe | dict(sensors or {})
    users = parse_assignments(explicit)
    if build is None:
        return own | users, ()
    known = build_parameters(build)
    for name in users:
        if name not in known:
            raise RigError(f"--param {name}: not a parameter of PX4 {build.tag} ({build.root})")
    lacking = tuple(name for name in own if name not in known)
    return {name: value for name, value in own.items() if name in known} | users, lacking


def parse_assignments(texts: tuple[str, ...]) -> dict[str, float]:
    """``--param NAME=VALUE`` texts as a mapping; a malformed one fails in one line."""
    params: dict[str, float] = {}
    for text in texts:
        name, sign, value = text.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sign or not name.strip() or not math.isfinite(number):
            raise RigError(f"--param {text!r}: expected NAME=VALUE with a finite number")
        params[name.strip()] = number
    return params


#: Where a PX4 build keeps its generated parameter metadata (names, types, ranges).
PARAMETER_METADATA = Path("etc/extras/parameters.json.xz")

#: The sticks of a replayed flight reach PX4 as MAVLink MANUAL_CONTROL from the rig's
#: onboard link (a joystick, in PX4's words), not from an RC receiver: "joystick only".
STICK_PARAMETERS: dict[str, float] = {"COM_RC_IN_MODE": 1}

_LINKS = "serial port or MAVLink link of the real board (SITL's links are the rig's ports)"
#: A real vehicle's parameters that never go into SITL, each with why (first match wins).
NOT_FROM_THE_VEHICLE: tuple[tuple[re.Pattern[str], str], ...] = tuple(
    (re.compile(pattern), reason)
    for pattern, reason in (
        (r"CAL_.*|TC_.*", "calibration of the real sensor chips (other device ids; the rig's "
                          "sensors are ideal, and PX4's calibration checks would fail)"),
        (r"SYS_AUTOSTART|SYS_AUTOCONFIG|SYS_HITL",
         f"PX4 SITL flies airframe {AIRFRAME} in lockstep (SYS_HITL 0)"),
        (r"SENS_EN_.*|SENS_BOARD_.*", "a sensor driver or the board's mounting in the real "
                                      "vehicle (the rig's chips are SITL's sensors)"),
        (r"SER_.*|MAV_\d_.*|UXRCE_.*|GPS_\d_.*|TEL_.*|RC_PORT_CONFIG|RC_INPUT_PROTO"
         r"|.*_PRT_CFG|.*_PORT_CFG", _LINKS),
        (r"PWM_.*|DSHOT_.*|UAVCAN_.*|HIL_ACT_.*",
         f"a hardware output (SITL's motors are simulator outputs, set by airframe {AIRFRAME})"),
        (r"IMU_GYRO_RATEMAX|IMU_INTEG_RATE", "lockstep: the rig sets it to its IMU rate"),
        (r"MAV_SYS_ID", "the SITL instance sets it (system id = instance + 1)"),
        (r"SDLOG_MODE", "the rig logs from boot to shutdown"),
        (r"COM_RC_IN_MODE", "the rig's sticks are MAVLink MANUAL_CONTROL: joystick only (1)"),
        (r"COM_CPU_MAX", "PX4 on posix reports no CPU load (SITL's rcS turns the check off)"),
        (r"CBRK_SUPPLY_CHK", "SITL has no power module (SITL's rcS sets this circuit breaker)"),
    )
)  # fmt: skip


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter of a PX4 build, as its metadata declares it."""

    name: str
    integer: bool
    low: float | None = None
    high: float | None = None
    values: frozenset[int] | None = None  # an enumeration's values
    bits: int | None = None  # a bitmask's defined bits

    def refusal(self, value: float) -> str | None:
        """Why ``value`` is not one this build knows (None: it is). Compared as PX4 stores
        it (float32), so a logged 0.01 equals a minimum of 0.01."""
        stored = float(np.float32(value))
        if self.integer and not float(value).is_integer():
            return f"not an integer (the build's {self.name} is INT32)"
        if self.low is not None and stored < float(np.float32(self.low)):
            return f"below this build's minimum {self.low:g}"
        if self.high is not None and stored > float(np.float32(self.high)):
            return f"above this build's maximum {self.high:g}"
        if self.values is not None and int(value) not in self.values:
            return f"not one of this build's values {sorted(self.values)}"
        if self.bits is not None and int(value) & ~self.bits:
            return f"sets bits this build does not define (mask {self.bits})"
        return None


def build_parameters(build: Px4Build) -> dict[str, ParameterSpec]:
    """Every parameter the build knows, from its generated metadata (what ``param set``
    accepts by name); a build without it fails in one line."""
    path = build.root / PARAMETER_METADATA
    try:
        entries = json.loads(lzma.decompress(path.read_bytes()))["parameters"]
        return {entry["name"]: _spec(entry) for entry in entries}
    except (OSError, lzma.LZMAError, ValueError, KeyError, TypeError) as error:
        raise Px4NotFound(
            f"{path}: cannot read the build's parameter metadata ({error}); the rig needs "
            "it to know which parameters this PX4 has"
        ) from None


def _spec(entry: dict[str, Any]) -> ParameterSpec:
    values, bits = entry.get("values"), entry.get("bitmask")
    return ParameterSpec(
        name=entry["name"],
        integer=entry["type"] == "Int32",
        low=entry.get("min"),
        high=entry.get("max"),
        values=None if values is None else frozenset(v["value"] for v in values),
        bits=None if bits is None else sum(1 << b["index"] for b in bits),
    )


def sitl_parameters(
    logged: Mapping[str, float], known: Mapping[str, ParameterSpec]
) -> tuple[dict[str, float], tuple[tuple[str, float, str], ...]]:
    """Split a real vehicle's parameters into those SITL takes as they are and those it must
    not, each ``(name, value, reason)``: not in this build, :data:`NOT_FROM_THE_VEHICLE`, or
    a value outside what this build defines (skipped, never clamped: the log may come from
    another PX4 version)."""
    applied: dict[str, float] = {}
    skipped = []
    for name in sorted(logged):
        value = logged[name]
        reason = _not_for_sitl(name, value, known.get(name))
        if reason is None:
            applied[name] = value
        else:
            skipped.append((name, float(value), reason))
    return applied, tuple(skipped)


def _not_for_sitl(name: str, value: float, spec: ParameterSpec | None) -> str | None:
    if spec is None:
        return "not a parameter of this PX4 build"
    for pattern, why in NOT_FROM_THE_VEHICLE:
        if pattern.fullmatch(name):
            return why
    return spec.refusal(value)


class Px4Sitl:
    """One PX4 process for one run: its work dir, parameters, console and ULog.

    The parameters are written for both of PX4's hooks (:class:`ParameterHook`), so a PX4
    of any release finds its own first in ``PATH``. ``build`` None prepares the work dir
    and parameters only; :meth:`command` then tells the user how to start PX4 by hand.
    """

    def __init__(self, build: Px4Build | None, run_dir: Path, instance: int,
                 params: Mapping[str, float]) -> None:  # fmt: skip
        self.build = build
        self.instance = instance
        self.work_dir = run_dir / "px4"
        self.bin_dir = self.work_dir / "bin"
        self.console_path = run_dir / "px4.log"
        self.ulog_path = run_dir / "px4.ulg"
        self._process: subprocess.Popen[bytes] | None = None
        #: The CPU PX4 is held to (:meth:`hold_to_one_cpu`); None before, or with one CPU.
        self.cpu: int | None = None
        # PX4 keeps its state in its work dir: parameters.bson (every parameter a run set,
        # a replay's in-flight ones too), dataman (the mission and the item it was at) and
        # its logs. A run folder used again (--force) must not start from the last run's:
        # a replay's mission then began at the last run's item, and no two runs were alike.
        if self.work_dir.exists():
            shutil.rmtree(self.work_dir)
        self.bin_dir.mkdir(parents=True)
        settings = [f"param set {name} {_px4_number(value)}" for name, value in params.items()]
        rig = "# Written by the rig: rcS sources it from PATH after the airframe"
        scripts = {
            "px4-rc.params": [f"{rig} (PX4 v1.14, v1.15)."],
            "px4-rc.simulator": [f"{rig} (PX4 v1.16 on), in place of the build's own, which it "
                                 "runs first.", ". ${R}etc/init.d-posix/px4-rc.simulator"],
        }  # fmt: skip
        for name, lines in scripts.items():
            (self.bin_dir / name).write_text("\n".join(["#!/bin/sh", *lines, *settings]) + "\n")
        if build is not None:
            self._link_commands(build)

    def _link_commands(self, build: Px4Build) -> None:
        """``bin/px4`` and a ``px4-<module>`` link to it for every module the build has."""
        for source in sorted(build.binary.parent.glob("px4*")):
            link = self.bin_dir / source.name
            if link.is_symlink() or link.exists():
                link.unlink()
            target = source if source.name in ("px4", "px4-alias.sh") else Path("px4")
            link.symlink_to(target)

    def command(self, px4_root: str = "$PX4_DIR/build/px4_sitl_default") -> str:
        """The shell command that starts this PX4 (printed for a PX4 started by hand)."""
        root = str(self.build.root) if self.build is not None else px4_root
        return (
            f"PATH={shlex.quote(str(self.bin_dir.resolve()))}:$PATH "
            f"PX4_SYS_AUTOSTART={AIRFRAME} {root}/bin/px4 -d -i {self.instance} "
            f"-w {shlex.quote(str(self.work_dir.resolve()))} {root}/etc"
        )

    def start(self) -> None:
        """Start PX4 in its own session, console to ``px4.log``."""
        assert self.build is not None, "a hand-started PX4 is not the rig's to start"
        search_path = f"{self.bin_dir.resolve()}:{os.environ.get('PATH', '')}"
        environment = dict(os.environ, PX4_SYS_AUTOSTART=str(AIRFRAME), PATH=search_path)
        with self.console_path.open("wb") as console:
            self._process = start_child(
                [str(self.bin_dir.resolve() / "px4"), "-d", "-i", str(self.instance),
                 "-w", str(self.work_dir.resolve()), str(self.build.etc)],
                cwd=self.work_dir, env=environment, stdin=subprocess.DEVNULL,
                stdout=console, stderr=subprocess.STDOUT,
            )  # fmt: skip

    def starting(self) -> bool:
        """Whether PX4's start-up script still runs: PX4 runs it with ``system()``, so until
        it ends PX4 has a child process (the shell)."""
        assert self._process is not None, "PX4 was not started"
        pid = self._process.pid
        try:
            return any((task / "children").read_text().strip()
                       for task in Path(f"/proc/{pid}/task").iterdir())  # fmt: skip
        except OSError:  # PX4 ended (or a thread did meanwhile): nothing runs for it any more
            return False

    def settle(self) -> bool:
        """Once PX4's start-up script has ended, hold it to one CPU (:attr:`cpu` says which);
        True then, False while the script still runs."""
        if self.starting():
            return False
        self.hold_to_one_cpu()
        return True

    def hold_to_one_cpu(self) -> int | None:
        """Hold every thread of PX4 to :func:`px4_cpu`'s CPU (threads it starts later
        inherit it); that CPU, None with a single CPU or once PX4 has ended."""
        assert self._process is not None, "PX4 was not started"
        cpu = px4_cpu()
        if cpu is None:
            return None
        tasks = Path(f"/proc/{self._process.pid}/task")
        held: set[int] = set()
        try:
            # Until no thread is new: one started meanwhile by a thread not yet held would
            # not inherit the CPU.
            while new := {int(task.name) for task in tasks.iterdir()} - held:
                for tid in new:
                    with contextlib.suppress(ProcessLookupError):  # the thread ended
                        os.sched_setaffinity(tid, {cpu})
                held |= new
        except FileNotFoundError:  # PX4 ended
            return None
        self.cpu = cpu
        return cpu

    def exit_description(self) -> str | None:
        """How PX4 ended (naming its console log), None while it runs or when not started."""
        how = None if self._process is None else exit_description(self._process)
        return None if how is None else f"PX4 {how}; its console is in {self.console_path}"

    def stop(self) -> None:
        """SIGINT (PX4 shuts down and closes its ULog), SIGKILL if it hangs; then keep the
        ULog beside ``rig.ulg``."""
        if self._process is not None:
            stop_process_group(self._process, STOP_GRACE_S)
        self._keep_ulog()

    def _keep_ulog(self) -> None:
        logs = sorted((self.work_dir / "log").glob("*/*.ulg"), key=lambda p: p.stat().st_mtime)
        if logs:
            shutil.copyfile(logs[-1], self.ulog_path)


def _px4_number(value: float) -> str:
    """PX4's ``param set`` text: integers without a decimal point (INT32 parameters)."""
    return str(int(value)) if float(value).is_integer() else repr(float(value))
