"""A toy robot language, added as a newcomer would add one: this folder and one
``register`` call (tests/test_toy_language.py), nothing in ``compensation/`` or ``cli/``.

A ``.toy`` file holds lines ``MOVE x y z a b c`` (the tool's pose in the robot base: mm and
Z-Y-X Euler degrees, as KUKA writes them) and ``TOOL name`` (the tool of the moves after
it, a tool of calib.json marked for programs); anything else is a comment. Its controller
takes, for each move, the branch of the arm inside the axis ranges nearest the previous
move's joints (nearest zero for the first)."""
