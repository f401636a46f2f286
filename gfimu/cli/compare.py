"""``gfimu compare``."""


def register(sub) -> None:
    p = sub.add_parser("compare", help="(compare: not available yet)")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotImplementedError("gfimu compare is not available yet")
