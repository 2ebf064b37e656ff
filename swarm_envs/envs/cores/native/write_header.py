"""Rewrite the committed copy of the C step's generated header (``include/step_params.h``).

Run ``python -m swarm_envs.envs.cores.native.write_header`` after a change to what the
header is generated from (:mod:`swarm_envs.envs.cores.native.contract`): the builds at
install compile against this copy, and a test fails while it differs from
:func:`~swarm_envs.envs.cores.native.contract.header`.
"""

from __future__ import annotations

import argparse

from swarm_envs.envs.cores.native.contract import header_path, write_header


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="fail where the copy differs")
    args = parser.parse_args(argv)
    if args.check:
        from swarm_envs.envs.cores.native.contract import header

        path = header_path()
        if not path.exists() or path.read_text() != header():
            raise SystemExit(f"{path} differs from the generated header; rewrite it")
        print(f"{path} is up to date")
        return
    print(write_header())


if __name__ == "__main__":
    main()
