"""The lens from straight lines, a checkerboard or one frame (``homocal lens``): lens.json for --camera-json."""
