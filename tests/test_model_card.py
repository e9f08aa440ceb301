"""Model cards of the bundled models: architecture and approach come from the training run."""

import json

from tools.commands.model_card import card


def _run(tmp_path, arch, approach):
    (tmp_path / "config.json").write_text(json.dumps({
        "config": {"arch": arch, "approach": approach, "batch_size": 256, "aug_loops": 8, "learning_rate": 0.001,
                   "seed": 0},
        "resolved": {"epochs": 2, "steps_per_epoch": 280, "deletion_rate": 0.7, "train_samples": 10,
                     "val_samples": 2, "zero_steer_train_samples": 5},
        "contract": {"width": 200, "height": 66}}))
    (tmp_path / "history.csv").write_text("epoch,train_loss,val_loss,seconds\n1,0.2,0.02,60\n2,0.1,0.0125,60\n")
    return tmp_path


SIM = {"laps": [{"eta": 100.0, "n_interventions": 0, "lap_time_s": 175.0, "mean_speed_kmh": 20.6,
                 "cte_rms_m": 0.3}], "config": {"track": "lake", "cones": 0, "speed_limit_kmh": 25}}


def test_a_pilotnet_card_names_its_architecture_approach_and_eval_command(tmp_path):
    text = card(_run(tmp_path, "pilotnet", "nvidia"), "simplistic", "rbc train ...", SIM, "pilotnet_nvidia.onnx")
    assert "NVIDIA's PilotNet (252,219 parameters" in text and "NVIDIA's approach (centre camera only" in text
    assert "| training time | 2.0 min on a 2-core CPU |" in text and "0.01250" in text
    assert "--model models/pretrained/pilotnet_nvidia.onnx --out eval/pilotnet_nvidia" in text


def test_a_behavior_model_card_uses_the_default_eval_command(tmp_path):
    text = card(_run(tmp_path, "shallow", "ours"), "simplistic", "rbc train ...", SIM, "simplistic.onnx")
    assert "shallow CNN (14,065 parameters" in text and "balancing lambda = 0.7" in text
    assert "`rbc eval --behavior simplistic --out eval/simplistic`" in text
