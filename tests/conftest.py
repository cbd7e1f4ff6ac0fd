"""Shared fixtures: the bundled nets and small generated meshes."""

from __future__ import annotations

import pytest

import fabplan
from fabplan.net.mesh import QuadMesh


@pytest.fixture(scope="session")
def wein99() -> QuadMesh:
    return QuadMesh.from_obj(fabplan.data_path("wein99.obj"))


@pytest.fixture(scope="session")
def cmc1() -> QuadMesh:
    return QuadMesh.from_obj(fabplan.data_path("cmc1.obj"))
