"""
What the command-line programs share.

``console`` holds the console scripts' entry points (``rotation_node``,
``rotation_bag``, ``rotation_scene``); ``stop_signal`` turns SIGINT/SIGTERM
into a flag the work checks; ``progress`` reports progress on a terminal;
``topic_arguments`` parses topic names given on the command line.
"""
