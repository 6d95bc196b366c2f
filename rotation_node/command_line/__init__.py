"""What the console scripts share: entry points, stop signals, progress, topic arguments."""
