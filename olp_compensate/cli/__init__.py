"""The two commands, olp-cal and olp-fix: argument parsing, printing and exit codes; the only
place that touches threads, signals, the garbage collector or the process exit."""
