"""Argument types shared by the `predvla` commands."""

import argparse
from collections.abc import Callable


def int_list(flag: str) -> Callable[[str], list[int]]:
    """An argparse `type` for `flag`: comma-separated integers and inclusive ranges ("0,3,5", "1-20"), returned
    sorted without repeats; anything else, or nothing, is refused naming the flag."""

    def parse(text: str) -> list[int]:
        out = []
        try:
            for part in text.split(","):
                part = part.strip()
                if not part:
                    continue
                if "-" in part:
                    lo, hi = (int(v) for v in part.split("-", 1))
                    if hi < lo:
                        raise ValueError(part)
                    out.extend(range(lo, hi + 1))
                else:
                    out.append(int(part))
        except ValueError as err:
            raise argparse.ArgumentTypeError(f"{flag} expects integers and ranges such as 1-20 or 0,3,5; got "
                                             f"{text!r}") from err
        if not out:
            raise argparse.ArgumentTypeError(f"{flag} is empty")
        return sorted(set(out))

    return parse
