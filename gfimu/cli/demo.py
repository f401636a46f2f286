"""``gfimu demo``."""


def register(sub) -> None:
    p = sub.add_parser("demo", help="(demo: not available yet)")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotImplementedError("gfimu demo is not available yet")
