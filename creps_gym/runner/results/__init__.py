"""What is made of runs: learning-curve plots, IOHanalyzer exports, groups of seeds, videos, and the
output files a user names (``-o``, ``--save``, ``--video``)."""
