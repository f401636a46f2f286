"""``gfimu evaluate``."""


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="(evaluate: not available yet)")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotImplementedError("gfimu evaluate is not available yet")
