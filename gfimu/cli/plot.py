"""``gfimu plot``."""


def register(sub) -> None:
    p = sub.add_parser("plot", help="(plot: not available yet)")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotImplementedError("gfimu plot is not available yet")
