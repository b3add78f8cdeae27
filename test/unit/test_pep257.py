# Copyright 2015 Open Source Robotics Foundation, Inc.
# Copyright 2026 etdmp_ros maintainers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Docstring conventions (ament_pep257, i.e. pydocstyle) over the package, tests, launch, tools."""

from pathlib import Path

from ament_pep257.main import main
import pytest

REPO = Path(__file__).resolve().parents[2]
# Only source paths are listed, so .venv*/, build/, install/, log/ and out/ are never visited;
# below them, pydocstyle skips every directory named '.*' or '_*'.
CHECKED = ('setup.py', 'etdmp_ros', 'test', 'launch', 'tools')


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    paths = [str(REPO / p) for p in CHECKED if (REPO / p).exists()]
    rc = main(argv=paths)
    assert rc == 0, 'Found code style errors / warnings'
