"""``gfimu calibrate``."""


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="(calibrate: not available yet)")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotImplementedError("gfimu calibrate is not available yet")
