"""`hamr-bench model actuator|leg`: evaluate the powertrain model from the command line (JSON or a text table)."""

from __future__ import annotations

import argparse
import json


def register(subparsers: argparse._SubParsersAction) -> None:
    from hamr_bench.model.designs import DEFAULT_KAPPA_UNITS, KAPPA_READINGS

    parser = subparsers.add_parser("model", help="evaluate the actuator or leg (powertrain) model")
    sub = parser.add_subparsers(dest="model_command", metavar="WHAT")

    a = sub.add_parser("actuator", help="bimorph actuator outputs vs bias voltage (one-sided, V_drive = V_bias)")
    a.add_argument("--layers", type=int, choices=(1, 2, 3), default=2)
    a.add_argument("--params", choices=("reported", "effective"), default="effective")
    a.add_argument("--voltage", type=float, nargs="+", default=[250.0], metavar="V")
    a.add_argument("--voltage-limit", type=float, default=250.0, metavar="V",
                   help="refuse voltages above this (default 250 V)")
    a.add_argument("--json", action="store_true")
    a.set_defaults(func=run_actuator)

    g = sub.add_parser("leg", help="lift powertrain tests of the paper (designs 1..5, 2-layer effective actuator)")
    g.add_argument("--design", type=int, choices=(1, 2, 3, 4, 5), required=True)
    g.add_argument("--test", choices=("blocked-force", "free-displacement", "static"), required=True)
    g.add_argument("--voltage", type=float, nargs="+", default=None, metavar="V")
    g.add_argument("--sag", type=float, nargs="+", default=None, metavar="S_m")
    g.add_argument("--force", type=float, nargs="+", default=None, metavar="F_N")
    g.add_argument("--layers", type=int, choices=(1, 2, 3), default=2)
    g.add_argument("--params", choices=("reported", "effective"), default="effective")
    g.add_argument("--voltage-limit", type=float, default=250.0, metavar="V")
    g.add_argument("--kappa-units", choices=tuple(KAPPA_READINGS), default=DEFAULT_KAPPA_UNITS,
                   help=f"reading of Table III's kappa units, with its geometry (default {DEFAULT_KAPPA_UNITS})")
    g.add_argument("--friction-mu", type=float, default=0.0, metavar="MU",
                   help="blocked-force test: Coulomb friction at the foot, the foot sliding as the drive presses "
                        "it (default 0, frictionless)")
    g.add_argument("--json", action="store_true")
    g.set_defaults(func=run_leg)
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])


def _check_voltages(values, limit: float) -> None:
    from hamr_bench.errors import ConfigError

    for v in values:
        if not (abs(v) <= limit):
            raise ConfigError(f"--voltage {v:g} V exceeds the configured limit {limit:g} V")


def _emit(points: list[dict], as_json: bool, meta: dict) -> None:
    if as_json:
        # NaN (e.g. a leg that collapses under the load) is not JSON: write null.
        clean = [{k: (None if isinstance(v, float) and v != v else v) for k, v in p.items()} for p in points]
        print(json.dumps({**meta, "points": clean}, indent=2))
        return
    for k, v in meta.items():
        print(f"# {k}: {v}")
    if points:
        keys = list(points[0])
        print("\t".join(keys))
        for p in points:
            print("\t".join(f"{p[k]:.6g}" for k in keys))


def run_actuator(args: argparse.Namespace) -> int:
    import numpy as np

    from hamr_bench.model import actuator_preset

    _check_voltages(args.voltage, args.voltage_limit)
    a = actuator_preset(args.layers, args.params)
    v = np.asarray(args.voltage, dtype=float)
    cols = dict(blocked_force_N=a.blocked_force_N(v), free_displacement_m=a.free_displacement_m(v),
                energy_J=a.energy_J(v), energy_density_J_per_kg=a.energy_density_J_per_kg(v))
    points = [dict(voltage_V=float(v[i]), blocked_force_N=float(cols["blocked_force_N"][i]),
                   free_displacement_m=float(cols["free_displacement_m"][i]),
                   stiffness_N_per_m=float(a.stiffness_N_per_m), mass_kg=float(a.mass_kg),
                   energy_J=float(cols["energy_J"][i]),
                   energy_density_J_per_kg=float(cols["energy_density_J_per_kg"][i])) for i in range(v.size)]
    _emit(points, args.json, dict(layers=args.layers, params=args.params, model="plain beam closed form",
                                  convention="one-sided, V_drive = V_bias = voltage"))
    return 0


def run_leg(args: argparse.Namespace) -> int:
    import numpy as np

    from hamr_bench.errors import ConfigError
    from hamr_bench.model import powertrain

    if not (0.0 <= args.friction_mu < 1.0):
        raise ConfigError(f"--friction-mu must be in [0, 1), got {args.friction_mu:g}")
    p = powertrain(args.design, layers=args.layers, params=args.params, voltage_limit_V=args.voltage_limit,
                   kappa_units=args.kappa_units)
    meta = dict(design=args.design, name=p.design.name, test=args.test, layers=args.layers, params=args.params,
                kappa_units=args.kappa_units)
    if args.test == "blocked-force":
        volts = args.voltage if args.voltage is not None else [100.0, 150.0, 200.0, 250.0]
        sags = args.sag if args.sag is not None else [0.0]
        _check_voltages(volts, args.voltage_limit)
        V, S = np.meshgrid(np.asarray(volts, float), np.asarray(sags, float), indexing="ij")
        F = p.blocked_force_N(V, S, friction_mu=args.friction_mu)
        points = [dict(voltage_V=float(v), sag_m=float(s), force_N=float(f))
                  for v, s, f in zip(V.ravel(), S.ravel(), F.ravel(), strict=True)]
        meta["convention"] = "V_drive = V_bias = voltage; sensor raised sag_m above the undriven neutral"
        meta["friction_mu"] = args.friction_mu
    elif args.test == "free-displacement":
        volts = args.voltage if args.voltage is not None else [100.0, 150.0, 200.0, 250.0]
        _check_voltages(volts, args.voltage_limit)
        v = np.asarray(volts, float)
        d = p.free_displacement_m(v)
        points = [dict(voltage_V=float(a), displacement_m=float(b)) for a, b in zip(v, d, strict=True)]
        meta["convention"] = "one-sided downward stroke from the undriven neutral, V_drive = V_bias"
    else:
        forces = args.force if args.force is not None else [10.6e-3 / 4]
        f = np.asarray(forces, float)
        if np.any(~np.isfinite(f)):
            raise ConfigError("--force must be finite")
        d = p.static_displacement_m(f)
        points = [dict(force_N=float(a), displacement_m=float(b)) for a, b in zip(f, d, strict=True)]
        meta["convention"] = "actuator undriven; displacement_m = sag (foot pushed up) under a downward force_N; " \
                             "NaN if the leg collapses"
    _emit(points, args.json, meta)
    return 0
