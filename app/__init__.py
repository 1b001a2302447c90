"""insitu's application: the command line, the GUI, acquisition, file formats and reports."""

from app.can_import import install as _install_can_import

_install_can_import()  # python-can imported without asammdf (app/can_import.py)
