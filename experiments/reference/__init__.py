"""Reference simulators run beside jaxgrid on the same inputs (commands and their helpers)."""
