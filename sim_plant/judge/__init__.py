"""The one judge of a sensor fault: the bound its error is judged against and the offset its
check adds (``bounds``), when the error left that bound (``detection``), and the yaw rate the
faulty command caused (``caused_yaw``).  The fault matrix, ``hil run``, the offline runs and the
campaigns all judge with it; it imports the car below it and none of them (import-linter:
``pyproject.toml``), so the offline analysis and the harness can each take it without the other.
"""
