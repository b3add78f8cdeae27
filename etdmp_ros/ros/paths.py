"""Where the package's installed files are: config/ and launch/ (share/etdmp_ros in ROS)."""

from pathlib import Path

PACKAGE = 'etdmp_ros'


def share_dir() -> Path:
    """
    Return the folder holding ``config/`` and ``launch/``.

    In a ROS install (colcon) that is ``share/etdmp_ros`` found through the ament index; in a
    source checkout installed editable into a venv (``make venv``) it is the repository root.
    """
    source_root = Path(__file__).resolve().parents[2]
    if (source_root / 'package.xml').is_file() and (source_root / 'config').is_dir():
        return source_root
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory(PACKAGE))
    except Exception as exc:   # noqa: B902 - PackageNotFoundError or no ament index at all
        raise FileNotFoundError(f'cannot find the {PACKAGE} share folder: {exc}') from None


def config_path(name: str) -> Path:
    """Return the path of ``config/<name>`` (e.g. ``scene.yaml``)."""
    path = share_dir() / 'config' / name
    if not path.is_file():
        raise FileNotFoundError(f'{path} does not exist')
    return path
