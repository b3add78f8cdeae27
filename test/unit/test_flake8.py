# Copyright 2017 Open Source Robotics Foundation, Inc.
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

"""flake8 (ament_flake8 configuration) over the package, tests, launch files and tools."""

from pathlib import Path

from ament_flake8.main import main_with_errors
import pytest

REPO = Path(__file__).resolve().parents[2]
# Only source paths are listed, so .venv*/, build/, install/, log/ and out/ are never visited;
# below them, ament_flake8 skips every directory named '.*' or '_*' (run from the repository).
CHECKED = ('setup.py', 'etdmp_ros', 'test', 'launch', 'tools')


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8(monkeypatch):
    monkeypatch.chdir(REPO)
    paths = [str(REPO / p) for p in CHECKED if (REPO / p).exists()]
    rc, errors = main_with_errors(argv=paths)
    assert rc == 0, 'Found %d code style errors / warnings:\n' % len(errors) + \
        '\n'.join(errors)
