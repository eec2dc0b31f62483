"""The example robot configurations, the DBC files they name and the systemd unit.

The build installs this directory as the package ``gateway.examples`` (setup.py,
pyproject.toml), so that ``wheelgate init`` finds these files in an installed wheelgate; this
file only makes the directory a package.
"""
