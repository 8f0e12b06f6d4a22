#!/usr/bin/env bash
# make demo: the end-to-end run on the simulated bench. Not there yet: say so plainly.
echo "make demo: the end-to-end demo (simulated bench → sweep → reconstruction) is not implemented yet." >&2
echo "See README.md, section 'Status', for what exists today." >&2
exit 1
