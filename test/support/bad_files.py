"""Forged and oversized demonstration files for the skill library and dmp_server."""

import io
import zipfile

import numpy as np


def forged_npy(path, shape):
    """Write a 289-byte .npy file whose header claims ``shape`` (float64): the issue's file."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {'descr': '<f8', 'fortran_order': False, 'shape': shape})
    data = header.getvalue()
    path.write_bytes(data + bytes(289 - len(data)))
    return path


def npz_bomb(path, rows):
    """Write an .npz whose 'positions' is ``rows`` x 2 zeros, deflated (10^8 rows: 1.5 MB)."""
    with zipfile.ZipFile(path, 'w', compression=zipfile.ZIP_DEFLATED) as archive:
        with archive.open('positions.npy', 'w', force_zip64=True) as member:
            np.lib.format.write_array_header_1_0(
                member, {'descr': '<f8', 'fortran_order': False, 'shape': (rows, 2)})
            chunk = bytes(16 * 1_000_000)
            for _ in range(rows // 1_000_000):
                member.write(chunk)
    return path


def big_csv(path, size):
    """Write a well-formed CSV demonstration of at least ``size`` bytes."""
    row = '0.1234567890123,0.9876543210987\n'
    path.write_text('x,y\n' + row * (size // len(row) + 1))
    return path
