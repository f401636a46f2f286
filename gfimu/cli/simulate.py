"""``gfimu simulate``."""


def register(sub) -> None:
    p = sub.add_parser("simulate", help="(simulate: not available yet)")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotImplementedError("gfimu simulate is not available yet")
