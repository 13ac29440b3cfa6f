"""hairport: adapt strand hairstyles to new characters.

This folder holds the command line and the shared kernel (settings, storage, typed records);
the folders ``solver/``, ``service/`` and ``worker/`` beside it are installed as
``hairport.solver``, ``hairport.service`` and ``hairport.worker`` (see docs/architecture.md)."""

__version__ = "0.1.0"
