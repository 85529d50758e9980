"""handsim.cli.teleop_commands: the teleop sub-commands' actions, split from handsim.cli.teleop."""

from handsim.cli import teleop, teleop_commands


def test_teleop_still_exports_the_moved_commands_as_the_same_objects():
    """Every function and constant that moved is importable from the old module, unchanged."""
    moved = [
        name
        for name, value in vars(teleop_commands).items()
        if name.startswith("_")
        and not name.startswith("__")
        and getattr(value, "__module__", teleop_commands.__name__) == teleop_commands.__name__
    ]
    assert {"_replay", "_live", "_sweep", "_generate", "_send", "_serve", "_config"} <= set(moved)
    for name in moved:
        assert getattr(teleop, name) is getattr(teleop_commands, name), name


def test_each_sub_command_dispatches_to_its_action():
    """The parser built in teleop.py runs the actions defined in teleop_commands.py."""
    import argparse

    parser = argparse.ArgumentParser()
    teleop.add_parser(parser.add_subparsers(dest="command"))
    for action in ("replay", "live", "sweep", "generate", "send", "serve"):
        argv = {
            "replay": ["teleop", "replay", "f.json"],
            "live": ["teleop", "live", "--udp", "9000"],
            "sweep": ["teleop", "sweep"],
            "generate": ["teleop", "generate", "out.json"],
            "send": ["teleop", "send", "f.json", "--udp", "9000"],
            "serve": ["teleop", "serve"],
        }[action]
        func = parser.parse_args(argv).func
        assert func is getattr(teleop_commands, f"_{action}"), action
