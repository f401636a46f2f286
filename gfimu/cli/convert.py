"""``gfimu convert``."""


def register(sub) -> None:
    p = sub.add_parser("convert", help="(convert: not available yet)")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotImplementedError("gfimu convert is not available yet")
