"""API keys: Bearer or X-API-Key; the owner is a hash of the key; no keys means no service."""

import pytest

from hairport.service.auth import check_configuration, owner_of
from hairport.settings import Settings

from .conftest import AUTH, KEY


def test_owner_is_a_hash_of_the_key():
    assert owner_of(KEY) == owner_of(KEY) != owner_of(KEY + "x")
    assert owner_of(KEY).startswith("k") and len(owner_of(KEY)) == 25 and KEY not in owner_of(KEY)


def test_keys_in_either_header(client):
    assert client.get("/v1/jobs", headers=AUTH).status_code == 200
    assert client.get("/v1/jobs", headers={"X-API-Key": KEY}).status_code == 200
    for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic " + KEY}, {"X-API-Key": ""}):
        response = client.get("/v1/jobs", headers=headers)
        assert response.status_code == 401 and response.json()["code"] == "unauthorized"
        assert response.headers["www-authenticate"] == "Bearer"


def test_a_service_without_keys_refuses_to_start():
    with pytest.raises(RuntimeError, match="HAIRPORT_API_KEYS"):
        check_configuration(Settings(api_keys="", insecure_dev=False))
    check_configuration(Settings(api_keys="", insecure_dev=True))
