"""The one settings object: environment variables with the prefix HAIRPORT_."""

from hairport.settings import Settings


def test_defaults_and_environment(monkeypatch):
    defaults = Settings()
    assert defaults.task_soft_time_limit < defaults.task_time_limit < defaults.visibility_timeout
    monkeypatch.setenv("HAIRPORT_API_KEYS", " one, two ,,")
    monkeypatch.setenv("HAIRPORT_CORS_ORIGINS", "https://a.example,https://b.example")
    monkeypatch.setenv("HAIRPORT_MAX_STRANDS", "10")
    settings = Settings()
    assert settings.api_key_list == ["one", "two"]
    assert settings.cors_origin_list == ["https://a.example", "https://b.example"]
    assert settings.max_strands == 10
