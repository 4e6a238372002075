"""``python -m marionette.cli``: the ``marionette`` command."""
import sys

from marionette.cli import main

sys.exit(main())
