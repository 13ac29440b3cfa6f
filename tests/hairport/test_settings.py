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


def test_storage_dir_is_absolute_whatever_the_working_directory(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HAIRPORT_STORAGE_DIR", "relative/data")
    assert Settings().storage_dir == tmp_path / "relative" / "data"
    monkeypatch.delenv("HAIRPORT_STORAGE_DIR")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    defaults = Settings()
    assert defaults.storage_dir == tmp_path / "xdg" / "hairport" and defaults.storage_dir.is_absolute()
    assert defaults.heartbeat_seconds < defaults.stale_after_seconds
    # a dead worker host's job is found stale within a minute of its last heartbeat: the threshold, then at
    # most one sweep period and one sweeper tick (TICKS_PER_PERIOD per period)
    assert defaults.stale_after_seconds + defaults.sweep_seconds * (1 + 1 / 3) <= 60
    assert defaults.max_attempts == 3 and defaults.memory_budget_bytes == 8 * 1024**3
