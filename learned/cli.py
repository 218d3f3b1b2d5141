"""``physrelight train ...``: the first stage's training, evaluation and weight export.

Sub-subcommands (heavy imports stay inside the handlers):

* ``train inverse --data DIR --out RUN``: the self-supervised inverse rendering network;
* ``train shadow --data DIR --out RUN --inverse RUN_OR_WEIGHTS``: ShadowNet on the
  inverse network's normals, lighting and shadows;
* ``train evaluate --data DIR [--split all] [--weights DIR] [--reference-weights DIR]``: held-out
  metrics of shipped (or exported) weights next to the trivial baselines, with scene-bootstrap
  intervals of the per-photo means, as JSON (with a reference: paired differences too);
* ``train export --inverse RUN [--shadow RUN] --dest DIR [--fill-from DIR]``: weights-only
  safetensors for :meth:`learned.Relighter.load` (the other pipeline files copied from a
  complete folder, e.g. the shipped one, with ``--fill-from``).
* ``train sky --data DIR --out RUN [--export PATH] [--evaluate DIR --json PATH]``: SkyGAN
  (:mod:`learned.train_sky`; reads ground-truth SH, not self-supervised), optionally exported
  and measured ("does the sky follow the SH") on held-out data;
* ``train segmentation --data DIR --out RUN [--export PATH] [--evaluate DIR --json PATH]``:
  the sky segmenter, optionally exported and scored (IoU vs trivial baselines).
* ``train renderer --data DIR --out RUN [--inverse W] [--shadow W] [--phase1-steps N]``: the
  neural renderer on the frozen inverse network + ShadowNet (:mod:`learned.train_renderer`);
* ``train export-renderer --run RUN [--step N]``: its generator as
  ``learned/weights/renderer.safetensors``;
* ``train evaluate-relight --data DIR [--json PATH]``: held-out relighting vs path tracing
  (l1 / SSIM / PSNR / CIEDE2000 of proposed, lambertian_sh, shadownet_lambertian, identity).

Re-running ``train inverse``/``train shadow`` with the same ``--out`` resumes from the
latest checkpoint. Under ``torchrun --nproc_per_node N`` the loops run distributed (NCCL on
CUDA, one GPU per rank; gloo on the CPU). ``--device``, ``--precision``, ``--workers`` and
``--preset paper`` on ``inverse``, ``shadow`` and ``renderer``: see docs/training.md.
"""

from __future__ import annotations

import argparse
import json
import sys

from physrelight.cli_common import positive_int


def _step_range(text: str) -> tuple[int, int]:
    """argparse type: ``FIRST:LAST``, two positive steps with FIRST < LAST (one-line error otherwise)."""
    first, sep, last = text.partition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected FIRST:LAST steps, got {text!r}")
    a, b = positive_int(first), positive_int(last)
    if a >= b:
        raise argparse.ArgumentTypeError(f"expected FIRST < LAST, got {text!r}")
    return a, b


def _loss_weights(items: list[str] | None, defaults: dict[str, float]) -> dict[str, float]:
    """``defaults`` with the ``--loss-weight NAME=VALUE`` overrides applied (unknown names refused)."""
    weights = dict(defaults)
    for item in items or []:
        name, _, value = item.partition("=")
        if name not in weights:
            raise ValueError(f"unknown loss weight {name!r}; known: {sorted(weights)}")
        weights[name] = float(value)
    return weights


def _write_json(path: str | None, data: dict) -> None:
    """Write metrics to ``path`` (atomically; nothing when None)."""
    if path:
        from physrelight import io

        io.write_json(path, data)


# ``--preset paper``: what Yu et al. (ECCV 2020) state of their training schedule. Only the resolution:
# the batch size, learning rate, optimizer and iterations are not stated in the text we could read
# (docs/training.md), so the project's defaults stand for them. Explicit flags override the preset.
PRESETS: dict[str, dict[str, object]] = {"paper": {"res": 200}}


def _compute_options(p: argparse.ArgumentParser) -> None:
    """Register ``--device``, ``--precision``, ``--workers`` and ``--preset`` on a training stage's parser.

    Call it after the stage's own ``set_defaults``: the options a preset sets get a ``None`` default
    (remembered in ``_preset_defaults``), so :func:`_compute_fields` can tell a flag given on the
    command line, which wins, from one left to the preset or the stage's default."""
    p.add_argument("--device", choices=("auto", "cpu", "cuda", "mps"), default="auto",
                   help="where to train: auto = cuda if available, else mps, else cpu (default: auto); a run "
                        "resumes on any device")
    p.add_argument("--precision", choices=("fp32", "bf16", "fp16"), default="fp32",
                   help="fp32 (default), or the networks under autocast in bf16 or fp16 (fp16 with a loss scaler); "
                        "losses and the lighting solve stay float32/float64; refused where this torch cannot run it")
    p.add_argument("--workers", type=int, default=0, metavar="N",
                   help="DataLoader processes making the batches, pinned memory on CUDA (default: 0 = in this "
                        "process); the same batches either way")
    p.add_argument("--preset", choices=sorted(PRESETS), default=None,
                   help="paper: the paper's stated schedule, i.e. 200 x 200 training photos (--res 200); its batch "
                        "size, learning rate and iterations are not stated, so the defaults stand (docs/training.md). "
                        "Explicit flags override the preset")
    defaults = {k: p.get_default(k) for k in sorted({k for preset in PRESETS.values() for k in preset})}
    p.set_defaults(_preset_defaults=defaults, **{k: None for k in defaults})


def _compute_fields(args: argparse.Namespace) -> dict[str, object]:
    """Settle the preset's options on ``args`` (a flag given explicitly is kept) and return the compute
    fields of a run configuration: ``device``, ``precision``, ``workers``."""
    if args.workers < 0:
        raise ValueError(f"--workers must be >= 0, got {args.workers}")
    preset = PRESETS.get(args.preset, {}) if args.preset else {}
    for key, default in args._preset_defaults.items():
        if getattr(args, key) is None:
            setattr(args, key, preset.get(key, default))
    return {"device": args.device, "precision": args.precision, "workers": args.workers}


def _config(args: argparse.Namespace, stage: str):
    from .objectives import LossWeights
    from .train import TrainConfig

    compute = _compute_fields(args)
    weights = _loss_weights(args.loss_weight, LossWeights().as_dict())
    return TrainConfig(stage=stage, data=args.data, out=args.out, val_data=args.val_data, val_split=args.val_split,
                       train_split=args.train_split,
                       width=args.width, depth=args.depth, res=args.res, batch=args.batch, steps=args.steps,
                       lr=args.lr, seed=args.seed, val_every=args.val_every, val_images=args.val_images,
                       ckpt_every=args.ckpt_every, log_every=args.log_every, threads=args.threads,
                       prior=args.prior, inverse=getattr(args, "inverse", None), init=args.init,
                       lighting_solve=getattr(args, "lighting_solve", "project"),
                       initial_shadow_logit=getattr(args, "initial_shadow_logit", 3.0),
                       mvs_stencil=getattr(args, "mvs_stencil", "central"), mirror=args.mirror,
                       mvs_pooled=getattr(args, "mvs_pooled", False), degrade=getattr(args, "degrade", False),
                       degrade_under_ev=getattr(args, "degrade_under_ev", 0.0),
                       **_data_selection_config(args), weights=weights, progress=not args.quiet, **compute)


def _train_inverse(args: argparse.Namespace) -> int:
    from .train import train

    result = train(_config(args, "inverse"))
    print(json.dumps(result, indent=1))
    return 0


def _train_shadow(args: argparse.Namespace) -> int:
    from .train import train

    result = train(_config(args, "shadow"))
    print(json.dumps(result, indent=1))
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    import torch

    from .evaluate import compare_decompositions, evaluate_relighter, scene_intervals
    from .relighter import Relighter

    torch.set_num_threads(args.threads)
    # Load both before the long evaluation, so a bad --reference-weights fails at once.
    relighter = Relighter.load(args.weights)
    reference = Relighter.load(args.reference_weights) if args.reference_weights is not None else None
    metrics, per_image = evaluate_relighter(relighter, args.data, args.split, args.max_images, return_per_image=True)
    metrics["intervals"] = scene_intervals(per_image)
    if reference is not None:
        ref_metrics, ref_per_image = evaluate_relighter(reference, args.data, args.split, args.max_images,
                                                        return_per_image=True)
        ref_metrics["intervals"] = scene_intervals(ref_per_image)
        metrics["reference"] = ref_metrics
        metrics["paired"] = compare_decompositions(per_image, ref_per_image)
    print(json.dumps(metrics, indent=1))
    _write_json(args.json, metrics)
    return 0


def _export(args: argparse.Namespace) -> int:
    from pathlib import Path

    from . import checkpoint as ckpt
    from .relighter import fill_weights_folder

    dest = Path(args.dest)
    if args.fill_from is not None and not Path(args.fill_from).is_dir():
        raise ValueError(f"--fill-from: no weights folder at {args.fill_from!r}")
    if args.shadow is None and args.shadow_step is not None:
        raise ValueError("--shadow-step needs --shadow")
    if args.inverse_average is not None and args.inverse_step is not None:
        raise ValueError("--inverse-average and --inverse-step exclude each other (the average ends at its last step)")
    average = None  # the inverse run's checkpoints to average, the last of which gives the metadata
    if args.inverse_average is not None:
        average = ckpt.checkpoints_between(args.inverse, *args.inverse_average)
    stages = [("inverse", args.inverse, args.inverse_step, average)]
    if args.shadow is not None:
        stages.append(("shadow", args.shadow, args.shadow_step, None))
    for kind, run, step, mean_of in stages:
        side = mean_of[-1] if mean_of else ckpt.checkpoint_at(run, step)
        extra = {}
        if kind == "inverse" and args.lighting_solve:
            extra["lighting_solve"] = args.lighting_solve
        if kind == "inverse" and args.mirror_average:
            extra["mirror_average"] = "1"
        if kind == "inverse" and args.meter_exposure:
            extra["meter_exposure"] = "1"
        path = ckpt.export_weights(side, dest / f"{kind}.safetensors", kind, extra=extra or None, average=mean_of)
        source = f"mean of {len(mean_of)} checkpoints {mean_of[0].name}..{side.name}" if mean_of else str(side)
        print(f"{kind}: {source} -> {path} ({path.stat().st_size / 1e6:.2f} MB)")
    if args.fill_from is not None:  # a candidate folder for `--weights`: the rest as in FILL_FROM
        for name in fill_weights_folder(dest, args.fill_from):
            print(f"{name}: {Path(args.fill_from) / name} -> {dest / name}")
    return 0


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, help="synth dataset folder (trains on its 'train' split)")
    p.add_argument("--out", required=True, help="run folder (re-run to resume)")
    p.add_argument("--val-data", default=None, help="dataset for validation (default: --data)")
    p.add_argument("--val-split", default="val", help="split validated on (default: val)")
    p.add_argument("--train-split", default="train", help="split trained on (default: train)")
    p.add_argument("--width", type=positive_int, default=16, help="UNet width (default: 16)")
    p.add_argument("--depth", type=positive_int, default=3, help="UNet levels (default: 3)")
    p.add_argument("--res", type=positive_int, default=64, help="training resolution (default: 64)")
    p.add_argument("--batch", type=positive_int, default=4, help="photo pairs per step and process (default: 4)")
    p.add_argument("--steps", type=positive_int, default=2000)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--val-every", type=positive_int, default=250)
    p.add_argument("--val-images", type=positive_int, default=96, help="held-out photos per validation")
    p.add_argument("--ckpt-every", type=positive_int, default=250)
    p.add_argument("--log-every", type=positive_int, default=10)
    p.add_argument("--threads", type=positive_int, default=2, help="torch CPU threads per process (default: 2)")
    p.add_argument("--prior", default=None, help="lighting prior .npz (default: the shipped one)")
    p.add_argument("--init", default=None, metavar="RUN_OR_WEIGHTS",
                   help="start from this run's latest checkpoint or exported weights of the same stage and "
                        "size (fine-tuning: a fresh optimizer; default: random initialisation)")
    p.add_argument("--loss-weight", action="append", metavar="NAME=VALUE",
                   help="override a loss weight (appearance, albedo, normal, cross, prior, shadow, normal_smooth)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _data_selection(p: argparse.ArgumentParser) -> None:
    """``--scenes`` and ``--sky``: which scenes of ``--data`` (a synth set, a COLMAP workspace or MegaDepth,
    found by its layout: learned.data.open_training_data) and where a photo collection's sky comes from."""
    p.add_argument("--scenes", default=None, metavar="A,B",
                   help="train on these scenes only (comma-separated; the split is then ignored; "
                        "`physrelight train scenes --data DIR` lists them)")
    p.add_argument("--sky", choices=("auto", "none"), default="auto",
                   help="a photo collection's photos without masks/NAME.png (COLMAP's mask convention, black = "
                        "sky): the shipped sky segmenter's sky, kept in memory (auto, default) or no sky (none)")


def _data_selection_config(args: argparse.Namespace) -> dict:
    return {"scenes": getattr(args, "scenes", None), "sky": getattr(args, "sky", "auto")}


def _list_scenes(args: argparse.Namespace) -> int:
    from physrelight.collections import find_layout, split_of

    from .data import list_scenes

    layout = find_layout(args.data)
    for name in list_scenes(args.data):
        print(f"{name}\t{split_of(name)}")
    print(f"{args.data}: {layout} layout", file=sys.stderr)
    return 0


def _add_data_stages(tsub: argparse._SubParsersAction) -> None:
    """``train scenes``: the scenes of a data folder and their splits."""
    p = tsub.add_parser("scenes", help="list the scenes of --data (synth set, COLMAP workspace(s) or MegaDepth) "
                                       "with their split")
    p.add_argument("--data", required=True, help="data folder")
    p.set_defaults(handler=_list_scenes)


def _mirror(p: argparse.ArgumentParser) -> None:
    p.add_argument("--mirror", action="store_true",
                   help="augment: mirror each photo pair left-right with probability 1/2 (scene, cameras and "
                        "lighting mirrored together; learned.data.mirror_view)")


def _train_sky_stage(args: argparse.Namespace) -> int:
    """``train sky`` / ``train segmentation``: train (or resume), then optionally export and measure."""
    from pathlib import Path

    from .train_sky import SKY_LOSS_WEIGHTS, SkyTrainConfig, export_sky, train_sky

    weights = _loss_weights(args.loss_weight, SKY_LOSS_WEIGHTS)
    cfg = SkyTrainConfig(stage=args.stage, data=args.data, out=args.out, val_data=args.val_data,
                         val_split=args.val_split, train_split=args.train_split, width=args.width, depth=args.depth,
                         res=args.res, batch=args.batch, steps=args.steps, lr=args.lr, lr_d=args.lr_d, seed=args.seed,
                         augment=not args.no_augment, val_every=args.val_every, val_images=args.val_images,
                         ckpt_every=args.ckpt_every, log_every=args.log_every, threads=args.threads, weights=weights,
                         progress=not args.quiet, wide_augment=args.wide_augment, dusk=args.dusk, clouds=args.clouds,
                         real_panoramas=args.real_panoramas,
                         real_exclude=tuple(args.real_exclude or ()), real_fraction=args.real_fraction,
                         real_views=args.real_views)
    result = train_sky(cfg)
    print(json.dumps(result, indent=1))
    if args.export:
        path = export_sky(args.out, args.export, average=args.export_average)
        print(f"{args.stage}: -> {path} ({path.stat().st_size / 1e3:.0f} kB)")
    if args.evaluate:
        from . import checkpoint as ckpt
        from .train_sky import build_sky_model, evaluate_segmentation, sky_follows_lighting

        model = build_sky_model(cfg)
        ckpt.load_checkpoint(ckpt.latest_checkpoint(args.out), model, restore_rng=False)
        if args.export and args.export_average:  # measure what was exported: the averaged weights
            from .sky_segmentation import load_sky_segmenter

            model["seg"] = load_sky_segmenter(args.export)
        if args.stage == "sky":
            panel = Path(args.json).with_suffix(".png") if args.json else None
            metrics = sky_follows_lighting(model["g"], args.evaluate, split="all", res=cfg.res, panel=panel)
        else:
            metrics = evaluate_segmentation(model["seg"], args.evaluate, split="all", res=cfg.res,
                                            fit_root=cfg.data, fit_split=cfg.train_split)
        print(json.dumps(metrics, indent=1))
        _write_json(args.json, metrics)
    return 0


def _add_sky_stages(tsub: argparse._SubParsersAction) -> None:
    """Register ``train sky`` (SkyGAN) and ``train segmentation`` (the sky segmenter)."""
    for stage, help_, width, batch, lr in (
            ("sky", "SkyGAN: SPADE sky generator + 2-scale PatchGAN (uses ground-truth SH)", 8, 8, 2e-4),
            ("segmentation", "sky segmentation UNet with photometric augmentation", 8, 16, 1e-3)):
        p = tsub.add_parser(stage, help=help_)
        p.add_argument("--data", required=True, help="synth dataset folder (trains on its 'train' split)")
        p.add_argument("--out", required=True, help="run folder (re-run to resume)")
        p.add_argument("--val-data", default=None, help="dataset for validation (default: --data)")
        p.add_argument("--val-split", default="val", help="split validated on (default: val)")
        p.add_argument("--train-split", default="train", help="split trained on (default: train)")
        p.add_argument("--width", type=positive_int, default=width, help=f"network width (default: {width})")
        p.add_argument("--depth", type=positive_int, default=3, help="UNet levels of the segmenter (default: 3)")
        p.add_argument("--res", type=positive_int, default=64, help="training resolution (default: 64)")
        p.add_argument("--batch", type=positive_int, default=batch, help=f"photos per step (default: {batch})")
        p.add_argument("--steps", type=positive_int, default=2000)
        p.add_argument("--lr", type=float, default=lr, help=f"learning rate (generator for sky; default: {lr})")
        p.add_argument("--lr-d", type=float, default=2e-4, help="discriminator learning rate (sky; default: 2e-4)")
        p.add_argument("--seed", type=int, default=0)
        p.add_argument("--no-augment", action="store_true", help="segmentation: no photometric augmentation")
        p.add_argument("--wide-augment", action="store_true",
                       help="segmentation: the wider camera (+-2 EV, white balance, dusk tints, JPEG-like blocks; "
                            "learned.sky_segmentation.WIDE_AUGMENT) and darkened dusk skies (dusk_sky)")
        p.add_argument("--dusk", action="store_true",
                       help="segmentation: darken and blue 30 %% of the photos' skies (learned.sky_segmentation.dusk_sky, "
                            "which --wide-augment also applies) and nothing else of the wider camera (study 57)")
        p.add_argument("--clouds", action="store_true",
                       help="segmentation: put clouds in half of the photos' skies, from dark dusk banks to white "
                            "(learned.sky_segmentation.cloud_sky; study 52)")
        p.add_argument("--real-panoramas", default=None, metavar="DIR",
                       help="segmentation: also train on random views of the real panoramas in DIR and their "
                            "NAME_sky.png masks (e.g. physrelight/data/hdri; a held-out panorama is refused)")
        p.add_argument("--real-exclude", action="append", metavar="NAME",
                       help="segmentation: leave this panorama out, from the real views and from the synthetic "
                            "photos it lights (repeatable; leave-one-panorama-out runs)")
        p.add_argument("--real-fraction", type=float, default=0.5,
                       help="segmentation: share of each batch taken from the real views (default: 0.5)")
        p.add_argument("--real-views", type=positive_int, default=1024,
                       help="segmentation: real views made once and drawn from (default: 1024)")
        p.add_argument("--val-every", type=positive_int, default=250)
        p.add_argument("--val-images", type=positive_int, default=96, help="validation photos")
        p.add_argument("--ckpt-every", type=positive_int, default=250)
        p.add_argument("--log-every", type=positive_int, default=10)
        p.add_argument("--threads", type=positive_int, default=1, help="torch CPU threads (default: 1)")
        p.add_argument("--loss-weight", action="append", metavar="NAME=VALUE",
                       help="sky: override a loss weight (gan, fm, lowres)")
        p.add_argument("--export", default=None, metavar="PATH", help="after training, export weights-only safetensors")
        p.add_argument("--export-average", default=None, type=_step_range, metavar="FIRST:LAST",
                       help="segmentation: export the mean of the checkpoints of steps FIRST..LAST")
        p.add_argument("--evaluate", default=None, metavar="DATA",
                       help="after training, held-out figures on DATA (all splits): sky IoU vs baselines, or "
                            "whether SkyGAN's sky follows the SH")
        p.add_argument("--json", default=None, help="write the --evaluate figures here (sky: and a PNG panel "
                                                      "beside it)")
        p.add_argument("--quiet", action="store_true", help="no progress bar")
        p.set_defaults(handler=_train_sky_stage, output_folders=("out",), output_files=("export", "json"))


def _train_renderer(args: argparse.Namespace) -> int:
    """``train renderer``: train (or resume) the neural renderer on frozen inverse network + ShadowNet."""
    from .renderer_objectives import RendererWeights
    from .train_renderer import RendererConfig, train_renderer

    compute = _compute_fields(args)
    weights = _loss_weights(args.loss_weight, RendererWeights().as_dict())
    cfg = RendererConfig(data=args.data, out=args.out, inverse=args.inverse, shadow=args.shadow, prior=args.prior,
                         val_data=args.val_data, val_split=args.val_split, train_split=args.train_split,
                         width=args.width, depth=args.depth, d_width=args.d_width, res=args.res, batch=args.batch,
                         steps=args.steps, phase1_steps=args.phase1_steps, cross_scale=args.cross_scale,
                         cross_match_scale=not args.cross_absolute, additive=not args.no_additive,
                         base=args.base, lr=args.lr,
                         lr_d=args.lr_d, seed=args.seed, val_every=args.val_every, val_images=args.val_images,
                         ckpt_every=args.ckpt_every, log_every=args.log_every, threads=args.threads, weights=weights,
                         progress=not args.quiet, **compute)
    print(json.dumps(train_renderer(cfg), indent=1))
    return 0


def _export_renderer(args: argparse.Namespace) -> int:
    from . import checkpoint as ckpt
    from .train_renderer import export_renderer

    side = ckpt.checkpoint_at(args.run, args.step)
    path = export_renderer(side, args.dest)
    print(f"renderer: {side} -> {path} ({path.stat().st_size / 1e6:.2f} MB)")
    return 0


def _evaluate_relight(args: argparse.Namespace) -> int:
    import torch

    from .relight_eval import evaluate_relight, format_table
    from .relighter import Relighter

    torch.set_num_threads(args.threads)
    pipe = Relighter.load(args.weights, args.renderer)
    if pipe.renderer is None:
        print("note: no renderer weights found; 'proposed' falls back to shadownet_lambertian")
    reference = None
    if args.reference_weights is not None:
        reference = Relighter.load(args.reference_weights).relight_linear
    result = evaluate_relight(pipe.relight_linear, args.data, args.split, args.res, args.max_cases,
                              progress=not args.quiet, reference=reference)
    print(format_table(result))
    _write_json(args.json, result)
    return 0


def _add_renderer_stages(tsub: argparse._SubParsersAction) -> None:
    """Register ``train renderer``, ``train export-renderer`` and ``train evaluate-relight``."""
    rn = tsub.add_parser("renderer", help="neural renderer on the frozen inverse network + ShadowNet (two phases)")
    _common(rn)
    rn.set_defaults(width=12, lr=5e-4, steps=3000, threads=1, val_every=500, ckpt_every=250)
    rn.add_argument("--inverse", default=None, help="inverse run folder or weights (default: the shipped ones)")
    rn.add_argument("--shadow", default=None, help="ShadowNet run folder or weights (default: the shipped ones)")
    rn.add_argument("--phase1-steps", type=int, default=2000,
                    help="steps of phase 1 (self-reconstruction + cross-projection); later steps add cycle "
                         "consistency and the GAN (default: 2000)")
    rn.add_argument("--cross-scale", type=positive_int, default=4,
                    help="cross-projection compared at 1/N resolution (default: 4)")
    rn.add_argument("--no-additive", action="store_true",
                    help="renderer output = Lambertian render x learned gain only (no additive term)")
    rn.add_argument("--base", choices=("lambertian", "quotient"), default="lambertian",
                    help="what the learned gain multiplies: the shadowed Lambertian render (the paper's; default) "
                         "or the quotient relighting of the photo")
    rn.add_argument("--cross-absolute", action="store_true",
                    help="compare cross-projections without the per-channel scale match")
    rn.add_argument("--d-width", type=positive_int, default=16, help="discriminator width (default: 16)")
    rn.add_argument("--lr-d", type=float, default=2e-4, help="discriminator learning rate (default: 2e-4)")
    rn.set_defaults(handler=_train_renderer, output_folders=("out",))
    _compute_options(rn)

    ex = tsub.add_parser("export-renderer", help="write the renderer's weights-only safetensors")
    ex.add_argument("--run", required=True, help="renderer run folder")
    ex.add_argument("--step", type=positive_int, default=None, help="checkpoint step (default: the latest)")
    ex.add_argument("--dest", default="learned/weights/renderer.safetensors",
                    help="destination file (default: learned/weights/renderer.safetensors)")
    ex.set_defaults(handler=_export_renderer, output_files=("dest",))

    ev = tsub.add_parser("evaluate-relight", help="held-out relighting vs path tracing: proposed vs baselines")
    ev.add_argument("--data", required=True, help="synth dataset folder with ground truth")
    ev.add_argument("--split", default="all", help="split to evaluate (default: all)")
    ev.add_argument("--weights", default=None, help="weights folder (default: the shipped ones)")
    ev.add_argument("--renderer", default=None, help="renderer weights (default: <weights>/renderer.safetensors)")
    ev.add_argument("--res", type=positive_int, default=64, help="resolution the pipeline runs at (default: 64)")
    ev.add_argument("--max-cases", type=positive_int, default=None, help="at most this many (source, target) cases")
    ev.add_argument("--reference-weights", default=None, metavar="FOLDER",
                    help="a second weights folder: its 'proposed' is scored as 'reference' on the same cases and "
                         "compared with a paired scene-bootstrap interval")
    ev.add_argument("--threads", type=positive_int, default=1)
    ev.add_argument("--json", default=None, help="also write the metrics here")
    ev.add_argument("--quiet", action="store_true", help="no progress bar")
    ev.set_defaults(handler=_evaluate_relight, output_files=("json",))


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``train`` with ``inverse``, ``shadow``, ``evaluate`` and ``export``."""
    p = sub.add_parser("train", help="train, evaluate and export the networks (inverse, ShadowNet, renderer, "
                                     "SkyGAN, sky segmenter)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    tsub = p.add_subparsers(dest="stage", required=True, metavar="STAGE")

    inv = tsub.add_parser("inverse", help="self-supervised inverse rendering network")
    _common(inv)
    _mirror(inv)
    _data_selection(inv)
    inv.add_argument("--lighting-solve", choices=("project", "map", "map_relative"), default="project",
                     help="lighting from the decomposition: least squares + orthogonal projection onto the prior's "
                          "subspace (the paper; default), the most probable lighting in the subspace (map), or the "
                          "same with the prior on the lighting's shape only, its level fitted (map_relative)")
    inv.add_argument("--initial-shadow-logit", type=float, default=3.0, metavar="X",
                     help="initial bias of the shadow head, s = sigmoid(X) at the start (default: 3, s = 0.95)")
    inv.add_argument("--mvs-stencil", choices=("central", "one_sided"), default="central",
                     help="normals of the MVS-like depth for the normal term: central differences (default) or "
                          "one-sided next to holes and edges (more supervised pixels)")
    inv.add_argument("--mvs-pooled", action="store_true",
                     help="take the normal term's MVS normals at the dataset's resolution and area-pool them to --res "
                          "(the dataset's resolution must be a multiple of --res; e.g. a 128-px set trained at 64)")
    inv.add_argument("--degrade", action="store_true",
                     help="augment: the network sees each photo with sensor noise, 8-bit quantisation and (half the "
                          "time) JPEG put back at --res, drawn as synth draws them; losses and the lighting solve "
                          "read the clean photo (learned.data.degrade_photo)")
    inv.add_argument("--degrade-under-ev", type=float, default=0.0, metavar="STOPS",
                     help="with --degrade: half the time the photo is also taken up to STOPS under-exposed (uniform) "
                          "and brought back after quantisation, as metering brings a dark photo back (default: 0)")
    inv.set_defaults(handler=_train_inverse, output_folders=("out",))
    _compute_options(inv)

    sh = tsub.add_parser("shadow", help="ShadowNet on a trained inverse network")
    _common(sh)
    _mirror(sh)
    _data_selection(sh)
    sh.add_argument("--inverse", required=True, help="inverse run folder or exported weights")
    sh.set_defaults(handler=_train_shadow, output_folders=("out",))
    _compute_options(sh)

    ev = tsub.add_parser("evaluate", help="held-out metrics of weights vs trivial baselines")
    ev.add_argument("--data", required=True, help="synth dataset folder with ground truth")
    ev.add_argument("--split", default="all", help="split to evaluate (default: all)")
    ev.add_argument("--weights", default=None, help="weights folder (default: the shipped ones)")
    ev.add_argument("--max-images", type=positive_int, default=None)
    ev.add_argument("--reference-weights", default=None, metavar="FOLDER",
                    help="a second weights folder, evaluated on the same photos ('reference'); 'paired' gives "
                         "the differences of the per-photo metrics with scene-bootstrap intervals")
    ev.add_argument("--threads", type=positive_int, default=2)
    ev.add_argument("--json", default=None, help="also write the metrics here")
    ev.set_defaults(handler=_evaluate, output_files=("json",))

    ex = tsub.add_parser("export", help="write weights-only safetensors for Relighter.load")
    ex.add_argument("--inverse", required=True, help="inverse run folder")
    ex.add_argument("--shadow", default=None,
                    help="shadow run folder (default: none exported; see --fill-from)")
    ex.add_argument("--inverse-step", type=positive_int, default=None,
                    help="inverse checkpoint step (default: the latest)")
    ex.add_argument("--inverse-average", type=_step_range, default=None, metavar="FIRST:LAST",
                    help="export the uniform mean of the inverse run's checkpoints with FIRST <= step <= LAST "
                         "(stochastic weight averaging; at least two)")
    ex.add_argument("--shadow-step", type=positive_int, default=None,
                    help="ShadowNet checkpoint step (default: the latest)")
    ex.add_argument("--dest", default="learned/weights", help="destination folder (default: learned/weights)")
    ex.add_argument("--fill-from", default=None, metavar="DIR",
                    help="then copy from DIR each pipeline file DEST lacks (shadow, lighting prior, renderer, sky "
                         "networks), e.g. learned/weights: a complete folder for --weights")
    ex.add_argument("--lighting-solve", choices=("project", "map", "map_relative"), default=None,
                    help="the lighting step the exported inverse network uses (default: the one it was trained with)")
    ex.add_argument("--mirror-average", action="store_true",
                    help="the exported inverse network averages each photo's layers with those of its mirror image "
                         "(two passes; learned.networks.mirror_averaged)")
    ex.add_argument("--meter-exposure", action="store_true",
                    help="the exported inverse network sees each photo re-metered to the training exposure "
                         "(learned.networks.metered), so its layers do not depend on the photo's exposure")
    ex.set_defaults(handler=_export, output_folders=("dest",))

    _add_sky_stages(tsub)
    _add_renderer_stages(tsub)
    _add_data_stages(tsub)
