"""Command-line front ends: thin ``main(argv) -> int`` functions over the library."""

import os

# The tools say what went wrong with a video or camera in their own words; OpenCV's FFmpeg and V4L2
# backends would print their own lines first. A user who wants those sets these variables.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
