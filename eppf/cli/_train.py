"""``eppf train``: fit a descriptor + classifier pipeline and save it as a model file.

The model file records how its objects were read (the sampling settings
and the per-file seed rule) so that ``eppf predict`` reads new files the
same way, and which objects it was trained on so that ``eppf evaluate``
can say when it is scored on them.
"""

import sys
import time

import numpy as np

from ..registry import CLASSIFIERS, DESCRIPTORS
from ._common import (CLASSIFIER_ALIASES, CLASSIFIER_NAMES, DEFAULT_N_PAIRS, Command, add_data_source, add_descriptor,
                      add_runtime, add_sampling, check_classes, check_not_input, check_output, descriptor_from_args,
                      load_labelled, count, fewest_points, positive_int, progress_of, register, sampling_from_args,
                      set_runtime, warn_tiny)

__all__ = ["make_pipeline_from_args", "run_train"]

MODEL_FORMAT = "eppf-model"


def add_arguments(p):
    add_data_source(p)
    p.add_argument("-o", "--output", required=True, metavar="MODEL", help="where to save the model")
    p.add_argument("--classifier", choices=CLASSIFIER_NAMES, default="kl",
                   help="a registered classifier: 'kl' (KLNearestNeighbors on the descriptors, the default), "
                        "'2d'/'3d'/'4d' (EPPF4DClassifier on EPPF descriptors), 'pointnet' (on the points); "
                        "'knn' and 'cnn' are eppf 0.1's names of 'kl' and '4d'")
    add_descriptor(p)
    p.add_argument("--n-bins", type=positive_int, nargs=4, default=None, metavar=("F1", "F2", "F3", "F4"),
                   help="bins of EPPF's four functions (default: the descriptor's)")
    p.add_argument("--n-neighbors", type=positive_int, default=None,
                   help="neighbours of the KL classifier (not of the normals: see --normal-neighbors); 'kl' only "
                        "(default: 1)")
    p.add_argument("--max-epochs", type=positive_int, default=None,
                   help="CNN/PointNet training epochs (default: 100)")
    p.add_argument("--recipe", choices=["recommended", "paper"], default=None,
                   help="how the 2d/3d/4d CNNs are trained: 'recommended' (default) describes every object 8 "
                        "times (stretched copies, a fresh draw every epoch, predictions averaged over copies), adds "
                        "GASD and 6 proportion ratios as side features, uses a smaller 4D network, halves the "
                        "learning rate on plateaus and computes in bfloat16 where the CPU does so natively; 'paper' "
                        "is the network of Table I on one EPPF descriptor per object, in float32 by default; "
                        "2d/3d/4d only")
    p.add_argument("--precision", choices=["auto", "float32", "bfloat16"], default=None,
                   help="CNN arithmetic: 'bfloat16' is mixed precision, faster on CPUs with native bfloat16 "
                        "(AVX512_BF16, AMX or ARM BF16), slower elsewhere; 'auto' chooses it only there (default: "
                        "auto with --recipe recommended, float32 with --recipe paper); 2d/3d/4d only")
    p.add_argument("--test-size", type=float, default=None,
                   help="fraction held out (stratified) to score the model when the data has no train/test "
                        "split; 0 trains on every object (default: 0.25; not with --all)")
    p.add_argument("--all", action="store_true", help="train on every object, ignoring a train/test split")
    add_sampling(p)
    add_runtime(p)


def _classifier_name(args):
    return CLASSIFIER_ALIASES.get(args.classifier, args.classifier)


#: Options of ``eppf train`` that one kind of classifier reads: (option, attribute, the classifiers that read it,
#: its value when not given). Given to another classifier, it would be ignored and recorded in the model as used.
CLASSIFIER_OPTIONS = (
    ("--n-neighbors", "n_neighbors", ("kl",), 1),
    ("--max-epochs", "max_epochs", ("2d", "3d", "4d", "pointnet"), 100),
    ("--recipe", "recipe", ("2d", "3d", "4d"), "recommended"),
    ("--precision", "precision", ("2d", "3d", "4d"), None),
)


def _classifier_options(args, name):
    """The classifier options' values (their defaults where not given); one given to a classifier that does not
    read it is refused, naming the option and the classifiers that read it."""
    values = {}
    for option, attr, readers, default in CLASSIFIER_OPTIONS:
        value = getattr(args, attr, None)
        if value is not None and name not in readers:
            only = " and ".join(readers) if len(readers) < 3 else ", ".join(readers[:-1]) + " and " + readers[-1]
            raise ValueError(f"{option}: the {name} classifier does not use it (only {only} "
                             f"{'does' if len(readers) == 1 else 'do'}); leave it out")
        values[attr] = default if value is None else value
    return values


def make_pipeline_from_args(args):
    """The Pipeline that ``eppf train`` fits for parsed arguments.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf train`` arguments.

    Returns
    -------
    pipeline : :class:`~sklearn.pipeline.Pipeline`
        An unfitted descriptor + classifier pipeline (the classifier alone
        for PointNet, which reads the points).

    Raises
    ------
    ValueError
        If the descriptor and classifier do not fit together.
    """
    from sklearn.pipeline import Pipeline

    progress = progress_of(args)
    name = _classifier_name(args)
    spec = CLASSIFIERS[name]
    cls = spec.estimator_class()
    torch_jobs = None if args.n_jobs < 0 else args.n_jobs
    options = _classifier_options(args, name)
    if spec.input == "points":
        # it reads the points: a descriptor option would be ignored, and the model would record it as used
        given = [o for o, v in (("--descriptor", args.descriptor != "eppf"),
                                ("--n-pairs", args.n_pairs != DEFAULT_N_PAIRS), ("--n-bins", args.n_bins is not None),
                                ("--scaling", args.scaling is not None),
                                ("--normal-neighbors", args.normal_neighbors is not None)) if v]
        if given:
            raise ValueError(f"{given[0]}: the {name} classifier reads the points, not a descriptor; leave it out")
        clf = cls(max_epochs=options["max_epochs"], random_state=args.random_state, n_jobs=torch_jobs,
                  verbose=1 if progress else 0)
        return Pipeline([("classifier", clf)])
    extra = {}
    if args.n_bins is not None:
        if DESCRIPTORS[args.descriptor].fixed.get("n_bins") is not None:
            raise ValueError(f"--n-bins: the {args.descriptor} descriptor has fixed bins; use --descriptor eppf")
        extra["n_bins"] = tuple(args.n_bins)
    descriptor = descriptor_from_args(args, progress, **extra)
    if name == "kl":
        if DESCRIPTORS[args.descriptor].metric != "kl":
            kl_names = ", ".join(k for k, s in DESCRIPTORS.items() if s.metric == "kl")
            raise ValueError(f"the {args.descriptor} descriptor is compared by L1, not by KL divergence; the "
                             f"'kl' classifier needs one of {kl_names}")
        clf = cls(n_neighbors=options["n_neighbors"], n_jobs=args.n_jobs)
    else:
        n_bins = descriptor.get_params().get("n_bins")
        # (the class through the registry, which imports it on use)
        if not isinstance(descriptor, DESCRIPTORS["eppf"].estimator_class()) or len(tuple(n_bins)) != 4:
            raise ValueError(f"the {name} classifier reads the 4D EPPF histogram; use --descriptor eppf or "
                             f"eppf_short, not {args.descriptor}")
        if options["recipe"] == "recommended":
            from ..registry import recommended_pipeline_parts

            descriptor, clf = recommended_pipeline_parts(
                descriptor, conv=spec.fixed.get("conv", "4d"), n_jobs=args.n_jobs, random_state=args.random_state,
                max_epochs=options["max_epochs"], verbose=1 if progress else 0)
            if options["precision"] is not None:
                clf.set_params(precision=options["precision"])
        else:
            clf = cls(n_bins=tuple(n_bins), **spec.fixed, max_epochs=options["max_epochs"],
                      precision=options["precision"] or "float32",
                      random_state=args.random_state, n_jobs=torch_jobs, verbose=1 if progress else 0)
    return Pipeline([("descriptor", descriptor), ("classifier", clf)])


def _check_saveable(model):
    """Refuse, before training, a pipeline the safe model format cannot hold."""
    from .._persist import ALLOWED

    for _, step in model.steps:
        cls = type(step)
        names = (f"eppf.{cls.__name__}", f"{cls.__module__.split('._')[0]}.{cls.__name__}")
        if not any(n in ALLOWED for n in names):
            raise ValueError(f"a model with {cls.__name__} cannot be saved by this eppf (its model format does "
                             "not hold that class yet); choose another --descriptor")


def _quiet(model):
    """No progress from the saved model, its fitted copies included (a Python user loading it sees none)."""
    set_runtime(model, None, False)


def _scores_line(scores):
    return (f"accuracy {100 * scores['total_accuracy']:.2f}%, mean class accuracy "
            f"{100 * scores['mean_class_accuracy']:.2f}%, macro F1 {100 * scores['macro_f1']:.2f}%")


def run_train(args, out=None):
    """Run ``eppf train``: fit a pipeline on a data set and save it as a model file.

    The saved object is a dict with ``"format"`` (``"eppf-model"``),
    ``"model"`` (the fitted Pipeline), ``"eppf_version"``, ``"params"`` (the
    command's arguments), ``"classes"`` (class names indexed by the model's
    labels), ``"data"`` (the training data's name), ``"sampling"`` (how
    files were read: ``n_points``, ``resolution``, ``normals``,
    ``random_state`` and ``seed_rule``), ``"train_ids"`` (the training
    objects, in the classifier's order) and ``"train_keys"`` (their resolved
    paths or data-set keys), written with :func:`eppf.save_model`.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``eppf train`` arguments.
    out : file-like, default=None
        Where the summary goes (standard output by default).

    Returns
    -------
    saved : dict
        What was written to ``args.output``.
    """
    from .. import __version__, save_model
    from ..metrics import retrieval_scores

    out = out or sys.stdout
    cmd = getattr(args, "prog", "eppf train")
    if args.all and args.test_size is not None:
        raise ValueError("--test-size: --all trains on every object and holds none out; leave one of them out")
    test_size = 0.25 if args.test_size is None else args.test_size
    if not 0 <= test_size < 1:
        raise ValueError(f"--test-size must be in [0, 1), got {test_size}")
    check_output(args.output)
    check_not_input(args.output, [("--data", args.data)])
    model = make_pipeline_from_args(args)
    _check_saveable(model)
    sampling = sampling_from_args(args)
    objects = load_labelled(args, sampling, cmd, min_points=fewest_points(model))
    y, class_names, name = objects.labels, objects.class_names, objects.name
    hold_out = not args.all and objects.split is None and test_size > 0
    check_classes(objects, cmd, need_two_per_class=hold_out)
    if args.all or (objects.split is None and test_size == 0):
        train = np.ones(len(y), dtype=bool)
        print(f"eppf train: training on all {count(len(y), 'object')} (nothing held out, so no held-out score)",
              file=out)
    elif objects.split is not None:
        train = objects.split == "train"
        if not train.any():
            raise ValueError(f"{name} has a split but no training objects")
        if args.test_size is not None:  # (as eppf run: the data's own split is the one scored)
            raise ValueError(f"--test-size: {name} has its own train/test split, which training uses; leave it out")
        print(f"eppf train: training on the {count(int(train.sum()), 'object')} of the train split, scoring on "
              f"the {int((~train).sum())} of the test split", file=out)
    else:
        from sklearn.model_selection import train_test_split

        idx, _ = train_test_split(np.arange(len(y)), test_size=test_size, stratify=y,
                                  random_state=args.random_state)
        train = np.zeros(len(y), dtype=bool)
        train[idx] = True
        print(f"eppf train: holding out {int((~train).sum())} of {len(y)} objects ({100 * test_size:g}%, "
              f"stratified) to score the model; --test-size 0 trains on all", file=out)
    fit_objects = objects.subset(train)
    if "descriptor" in model.named_steps:
        warn_tiny(fit_objects.clouds, fit_objects.ids, model.named_steps["descriptor"], cmd, args.descriptor)
    t0 = time.perf_counter()
    model.fit(fit_objects.clouds, fit_objects.labels)
    seconds = time.perf_counter() - t0
    _quiet(model)
    held = ~train
    scores = None
    if held.any():
        test_objects = objects.subset(held)
        scores = retrieval_scores(test_objects.labels, model.predict(test_objects.clouds))
        print(f"eppf train: held-out score on {count(int(held.sum()), 'object')}: {_scores_line(scores)}", file=out)
    params = {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(args).items()
              if k not in ("func", "prog")}
    # the values used (the defaults of the options not given); an option the classifier does not read stays None
    readers = {attr: r for _, attr, r, _ in CLASSIFIER_OPTIONS}
    params.update({k: v for k, v in _classifier_options(args, _classifier_name(args)).items()
                   if _classifier_name(args) in readers[k]}, test_size=test_size)
    saved = {"format": MODEL_FORMAT, "model": model, "eppf_version": __version__, "params": params,
             "classes": [str(c) for c in class_names], "data": str(name), "sampling": objects.sampling or sampling,
             "train_ids": [str(i) for i in fit_objects.ids], "train_keys": list(fit_objects.keys)}
    if scores is not None:
        saved["held_out_scores"] = {k: float(v) for k, v in scores.items() if np.isscalar(v)}
    save_model(saved, args.output)
    print(f"eppf: trained {args.classifier} on {count(int(train.sum()), 'object')} of {name} "
          f"({count(len(class_names), 'class', 'classes')}) "
          f"in {seconds:.1f} s -> {args.output}", file=out)
    return saved


register(Command(
    "train", "fit a descriptor + classifier pipeline on a data set and save it",
    "Fit a Pipeline (a registered descriptor + a registered classifier: 1-NN by symmetric KL, the EPPF CNNs, or "
    "PointNet on the points) on the training objects of a data set and save it as a model file (a zip of JSON "
    "and arrays that loading cannot turn into code), with its parameters, how its files were read and the "
    "eppf version. Without a train/test split, --test-size of the objects are held out and scored.",
    add_arguments, run_train,
))
