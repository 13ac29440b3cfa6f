"""hairport: adapt strand hairstyles to new characters."""
__version__ = "0.1.0"
