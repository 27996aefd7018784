"""`fleetcal profiles list|show|set` and `runs list|show` against a real `fleetcal serve`."""

from __future__ import annotations

import json
from pathlib import Path

from tests.client.conftest import ROBOT, Served
from tests.client.test_upload import cli, fake_mcap, upload_cli


def test_profiles_set_from_yaml_then_list_and_show(api_only: Served, tmp_path: Path) -> None:
    profile = tmp_path / "strict.yaml"
    profile.write_text("robot_model: tiny-bot\nlimits:\n  max_metric_error_m: 0.004\n")
    key = ("--url", api_only.url, "--key", api_only.admin_key)
    created = cli("profiles", "set", "strict", str(profile), *key)
    assert created.exit_code == 0, created.output
    assert json.loads(created.stdout)["limits"]["max_metric_error_m"] == 0.004
    listed = json.loads(cli("profiles", "list", *key).stdout)
    assert [p["name"] for p in listed["items"]] == ["strict"]
    shown = json.loads(cli("profiles", "show", "strict", *key).stdout)
    assert shown["robot_model"] == "tiny-bot"


def test_profiles_refusals_exit_2_with_the_problem(api_only: Served, tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("limits:\n  max_metric_error_m: -1\n")
    key = ("--url", api_only.url, "--key", api_only.admin_key)
    refused = cli("profiles", "set", "strict", str(bad), *key)
    assert refused.exit_code == 2 and "HTTP 422" in refused.output
    missing = cli("profiles", "show", "nope", *key)
    assert missing.exit_code == 2 and "HTTP 404" in missing.output
    not_a_mapping = tmp_path / "list.yaml"
    not_a_mapping.write_text("- 1\n")
    assert "must be a mapping" in cli("profiles", "set", "x", str(not_a_mapping), *key).output
    upload_key = cli("profiles", "set", "x", str(bad), "--url", api_only.url,
                     "--key", api_only.upload_key)  # fmt: skip
    assert upload_key.exit_code == 2 and "HTTP 403" in upload_key.output


def test_runs_list_with_filters_and_show(api_only: Served, tmp_path: Path) -> None:
    run_id = upload_cli(api_only, fake_mcap(tmp_path / "r.mcap", 4096)).stdout.strip()
    key = ("--url", api_only.url, "--key", api_only.admin_key)
    page = json.loads(cli("runs", "list", *key, "--robot", ROBOT, "--status", "queued").stdout)
    assert [run["id"] for run in page["items"]] == [run_id]
    none = json.loads(cli("runs", "list", *key, "--kind", "maintenance").stdout)
    assert none["items"] == []
    assert json.loads(cli("runs", "list", *key, "--passed").stdout)["items"] == []
    shown = json.loads(cli("runs", "show", run_id, *key).stdout)
    assert shown["status"] == "queued" and shown["robot_id"] == ROBOT
    bad_since = cli("runs", "list", *key, "--since", "yesterday")
    assert bad_since.exit_code == 2 and "HTTP 4" in bad_since.output
