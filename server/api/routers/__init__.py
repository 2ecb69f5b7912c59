"""One router per pendant menu: controllers, robot, tool, base, fixed tool, workpiece, sessions,
export (``tables`` and ``common`` hold what several of them share)."""
