"""JEPA configuration (LeWorldModel's numbers where they fit a CPU, docs/reference.md)."""
from __future__ import annotations

from dataclasses import dataclass

from wmdist.config.fields import MAX_LAYERS, param, section
from wmdist.search.cem import CEMConfig

GOAL_COSTS = ("last", "sum", "min")  # the planning costs of wmdist/algos/jepa/planning.py


@dataclass
class JepaConfig:
    """The `algo` section for JEPA: encoder, projector, predictor, SIGReg and a goal-reaching CEM planner."""

    # --- encoder and projector --------------------------------------------------------
    cnn_depth: int = param(16, "channels of the first of four stride-2 convs on a 64x64 frame (LeWM: a ViT-tiny)", ge=1)
    embed_dim: int = param(32, "embedding width D after the projector (LeWM: 192)", ge=1)
    proj_hidden: int = param(256, "hidden width of the projector MLP (LeWM: a BatchNorm projector)", ge=1)
    proj_out_norm: bool = param(True, "end the projector with a BatchNorm (LeWM's). It holds every embedding dimension "
                                      "at unit variance whatever the loss, so with sigreg_weight 0 the embedding "
                                      "cannot collapse to a point; false leaves SIGReg alone against collapse")
    bn_frames: int = param(512, "frames of the latest batches on which the learner re-estimates the projector's "
                                "BatchNorm statistics with the current weights before each publish (planning uses "
                                "them); 0 = torch's running average over ~10 batches, under which success swung "
                                "between 35% and 95% from one published version to the next", ge=0)
    # --- predictor --------------------------------------------------------------------
    history: int = param(1, "embeddings and actions the predictor sees (LeWM: 3; the point mass is Markov in one frame)",
                         ge=1)
    pred_hidden: int = param(256, "hidden width of the predictor MLP (LeWM: a 6-layer transformer)", ge=1)
    pred_layers: int = param(2, "hidden layers of the predictor MLP", ge=1, le=MAX_LAYERS)
    pred_dropout: float = param(0.0, "dropout after each hidden layer of the predictor while training (LeWM: 0.1); "
                                     "off when planning", ge=0, lt=1)
    rollout_steps: int = param(1, "K: the predictor is trained on its own K-step open-loop rollouts from each window's "
                                  "first history, as planning uses it, each step's MSE against the real embedding "
                                  "(1 = LeWM's teacher-forced next-step loss at every step); needs replay.seq_len >= "
                                  "history + K", ge=1, le=MAX_LAYERS)
    act: str = param("silu", "activation", choices=("elu", "silu", "relu", "tanh"))
    # --- loss -------------------------------------------------------------------------
    sigreg_weight: float = param(0.09, "lambda of MSE + lambda x SIGReg (LeWM: 0.09); 0 = the collapse ablation", ge=0)
    sigreg_projections: int = param(256, "random unit directions M drawn afresh every update (LeWM: 1024)", ge=1)
    sigreg_knots: int = param(17, "trapezoid knots K of the Epps-Pulley integral (LeWM: 17)", ge=2)
    sigreg_t_max: float = param(3.0, "upper end of the integral over t (LeWM: 3)", gt=0)
    sigreg_head: int = param(0, "hidden width of a BatchNorm MLP head that SIGReg tests instead of the embedding "
                                "itself (LeJEPA: regularise a projector, use the features below it), so the "
                                "embedding planning compares need not become an isotropic Gaussian; 0 = SIGReg on "
                                "the embedding (LeWM). nav:tworooms seeds 0-2: 47/77/43% of 100 goals against "
                                "76/51/49% on the embedding (BENCHMARKS.md)", ge=0)
    sigreg_head_dim: int = param(16, "output width of that head (the dimension of SIGReg's Gaussian)", ge=1)
    # --- optimisation -----------------------------------------------------------------
    lr: float = param(3e-4, "Adam learning rate", gt=0)
    publish_ema: float = param(0.0, "decay per update of an exponential moving average of the weights that the "
                                     "evaluator plans with and checkpoints keep (Polyak averaging; not in LeWM), its "
                                     "BatchNorm statistics re-estimated for the average; 0 publishes the learner's "
                                     "own weights", ge=0, lt=1)
    grad_clip: float = param(100.0, "gradient norm clip (0 = none)", ge=0)
    # --- acting -----------------------------------------------------------------------
    planner: CEMConfig = section(CEMConfig, "CEM planner toward the goal embedding, run at every step (MPC; "
                                            "LeWM: J 300, K 30, I 30)")
    goal_cost: str = param("last", "planning cost: last = squared distance of the last predicted embedding to the goal's "
                                   "(LeWM); sum = summed over every predicted step (fixes the first action); min = the "
                                   "closest approach over the horizon",
                           choices=GOAL_COSTS)
    step_cost: float = param(0.0, "with goal_cost min: added per imagined step before the minimum, min_k (d_k + "
                                  "step_cost x k), so of two plans that reach the goal the earlier one wins (a shorter "
                                  "path, not a detour); in units of squared embedding distance", ge=0)
    graph_pairs: int = param(0, "transitions (two consecutive real frames) of the latest batches whose embeddings the "
                                "learner publishes with the weights: the nodes of a graph on which the planner finds "
                                "waypoints toward far goals (Search on the Replay Buffer, waypoints.py); 0 = plan "
                                "straight to the goal (LeWM)", ge=0)
    graph_knn: int = param(5, "links from each graph node to its nearest nodes in embedding space", ge=0)
    graph_link: float = param(2.0, "the longest such link, in median steps. A fold of the embedding can put frames on "
                                   "either side of a wall 0.3 steps apart (a shortcut), but a cut-off that tight "
                                   "splits the graph: 0.3 planned to 66% of 100 goals where 2 did 80% (BENCHMARKS.md)",
                           gt=0)
    waypoint_steps: float = param(6.0, "with a graph: plan toward the node this many steps along the shortest path to "
                                       "the goal, or to the goal itself once it is nearer", gt=0)
    explore_keep: float = param(0.8, "collectors act at random (reward-free data): probability that a step keeps "
                                     "the previous random action, so runs go straight and cross rooms", ge=0, lt=1)

    def validate(self) -> None:
        """One-line ValueError for combinations the ranges alone can't catch."""
        try:
            self.planner.validate()
        except ValueError as err:
            raise ValueError(f"algo.{err}") from None
        if self.step_cost and self.goal_cost != "min":  # a constant under last and sum: it would change nothing
            raise ValueError(f"algo.step_cost ({self.step_cost}) only acts with algo.goal_cost: min, not "
                             f"{self.goal_cost!r}; set algo.step_cost=0 with it")
