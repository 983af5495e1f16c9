"""``python -m boucwen.diagnosis``: prints the diagnosis's rules, each with its reason (the
table of docs/diagnosis.md, :func:`boucwen.diagnosis.rules.markdown`)."""

import sys

from .rules import markdown

sys.stdout.write(markdown() + "\n")
