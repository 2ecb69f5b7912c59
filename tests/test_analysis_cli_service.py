"""``pendant analyze FILE --service URL``: the recording goes to a real service, the analysis
runs there as a job (202, followed to its end), and the stored report is printed."""

from __future__ import annotations

import json

import pytest
from browser_helpers import free_port, serve

from server.cli.main import main
from solvers.physics import Imperfections
from solvers.simulate import simulate_recording


@pytest.fixture(scope="module")
def service(tmp_path_factory):  # noqa: ANN001, ANN201
    """The real service; the CLI logs in with its Administrator's token from $PENDANT_TOKEN."""
    import os

    from api_helpers import ADMIN_TOKEN

    db = tmp_path_factory.mktemp("cli-service") / "pendant.db"
    saved = os.environ.get("PENDANT_TOKEN")
    os.environ["PENDANT_TOKEN"] = ADMIN_TOKEN
    try:
        with serve(f"sqlite:///{db}") as url:
            yield url
    finally:
        if saved is None:
            del os.environ["PENDANT_TOKEN"]
        else:
            os.environ["PENDANT_TOKEN"] = saved


def write(tmp_path, n: int, **effects) -> str:  # noqa: ANN001
    imp = Imperfections(noise_mm=0.02, **effects)
    path = tmp_path / "rec.json"
    path.write_text(json.dumps(simulate_recording("tracker", "ur10", imp, n, seed=5,
                                                  payload=(5.0, [0, 0, 50]))))
    return str(path)


def test_analyze_on_the_service_follows_the_job_and_prints_the_stored_report(service, tmp_path,
                                                                             capsys):
    path = write(tmp_path, 40, compliance_deg_per_Nm=(0, 5e-4, 0, 0, 0, 0))
    assert main(["analyze", path, "--service", service, "--json"]) == 0
    out = capsys.readouterr()
    rep = json.loads(out.out)
    assert (rep["findings"][0]["effect"], rep["findings"][0]["joint"]) == ("joint_compliance", 2)
    assert rep["id"] >= 1 and rep["recording_id"] >= 1  # stored on the service
    assert "job " in out.err  # its progress was shown


def test_a_refused_recording_and_a_missing_service_are_named_errors(service, tmp_path, capsys):
    assert main(["analyze", write(tmp_path, 3), "--service", service]) == 2
    err = capsys.readouterr().err
    assert "pendant: body.samples:" in err and "(422)" in err, err
    url = f"http://127.0.0.1:{free_port()}"
    assert main(["analyze", write(tmp_path, 40), "--service", url]) == 2
    assert f"pendant: --service: no answer from {url}" in capsys.readouterr().err
