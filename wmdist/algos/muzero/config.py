"""MuZeroConfig: the `algo` section of a MuZero run (every field documented where declared)."""
from __future__ import annotations

from dataclasses import dataclass

from wmdist.config.fields import MAX_LAYERS, param, section
from wmdist.nets.optim import OptimConfig
from wmdist.search.api import SearchConfig


def _muzero_optim() -> OptimConfig:
    # Paper: SGD momentum 0.9, weight decay 1e-4, lr 0.05 decayed x0.1 over 350k updates.
    return OptimConfig(kind="sgd", lr=0.05, momentum=0.9, weight_decay=1e-4, schedule="step",
                       decay_steps=350_000, decay_rate=0.1)


@dataclass
class MuZeroConfig:
    search: SearchConfig = section(SearchConfig, "batched MCTS settings (simulations, pUCT, noise, discount)")
    optim: OptimConfig = param(_muzero_optim(), "optimiser (paper: SGD momentum 0.9, wd 1e-4, lr 0.05)")

    # networks
    network: str = param("auto", "network family: mlp (vector obs), conv (images) or auto", choices=("auto", "mlp", "conv"))
    latent_dim: int = param(64, "mlp: hidden-state width", ge=1)
    # typed elements: a bare `list` let [1.5] through (a width-1 net) and [[1]] crash validate()
    hidden: list[int] = param([64], "mlp: hidden layer widths of every function; conv: widths of the head MLPs", ge=1)
    conv_channels: int = param(256, "conv: channels of the residual towers (paper: 256)", ge=2)
    conv_blocks: int = param(16, "conv: residual blocks in each of h, g, f (paper: 16)", ge=0, le=MAX_LAYERS)
    conv_head_channels: int = param(2, "conv: channels of the 1x1 conv before each head", ge=1)
    conv_stem: str = param("atari", "conv: representation input stage: atari = the paper's downsampling (96x96 -> 6x6); "
                                    "grid = one 3x3 conv at full resolution (small grids such as MinAtar's 10x10)",
                           choices=("atari", "grid"))
    conv_downsample_blocks: list[int] = param(
        [2, 3, 3], "conv, atari stem: residual blocks in the three stages of the 96 -> 6 downsampling (paper: 2, 3, 3)",
        ge=0)
    value_support: int = param(300, "value atoms cover the integers [-S, S] after h(x) (paper: 300)", ge=1)
    reward_support: int = param(300, "reward atoms cover the integers [-S, S] after h(x) (paper: 300)", ge=1)

    tree_model: str = param("learned", "what the search plans with: learned = MuZero's dynamics network; rules = the "
                                       "env's true rules (board games only: AlphaZero's perfect model; the network then "
                                       "evaluates each searched position from its observation)",
                            choices=("learned", "rules"))

    # learning targets and loss
    unroll_steps: int = param(5, "K: dynamics steps unrolled per sample (paper: 5)", ge=1)
    td_steps: int = param(10, "n of the n-step value target (paper: 10 Atari, 5 Reanalyze; board games: >= game length)", ge=1)
    bootstrap: str = param("search_value", "value bootstrap: stored search_value (refreshed by reanalyze) or a target network",
                           choices=("search_value", "target"))
    target_update_every: int = param(100, "updates between target-network refreshes (bootstrap=target)", ge=1)
    publish_ema: float = param(0.0, "decay per update of an exponential moving average of the weights that actors, "
                                     "reanalyzers, the evaluator and checkpoints get (Polyak averaging; not in the "
                                     "papers); 0 publishes the learner's own weights", ge=0, lt=1)
    publish_ema_to: str = param("all", "who acts on that average: all (collectors, reanalyzers, evaluator, checkpoints) "
                                       "or eval (the evaluator and checkpoints; collectors and reanalyzers act on the "
                                       "learner's own weights, so the data and targets do not lag)",
                                choices=("all", "eval"))
    value_loss_weight: float = param(1.0, "weight of the value loss (Reanalyze paper: 0.25)", ge=0)
    reward_loss_weight: float = param(1.0, "weight of the reward loss", ge=0)
    policy_loss_weight: float = param(1.0, "weight of the policy loss", ge=0)
    dynamics_grad_scale: float = param(0.5, "gradient scale at the dynamics input (paper: 1/2)", ge=0, le=1)
    priority_eps: float = param(1e-6, "added to |value error| so every sample keeps a chance", gt=0)
    bf16: bool = param(False, "run the learner's forward pass under CPU bfloat16 autocast")
    reanalyze_noise: bool = param(True, "Dirichlet root noise in reanalyze searches, as in self-play (EfficientZero does "
                                        "this); without it a peaked prior can take every visit and the targets collapse")
    augment_symmetries: bool = param(False, "board games: train each sample on a random rotation/reflection of the board "
                                            "(AlphaGo Zero's augmentation; not in the MuZero paper)")

    # acting
    visit_temperatures: list[float] = param([1.0, 0.5, 0.25], "visit-count temperatures in turn (paper Atari: 1, 0.5, 0.25)", ge=0)
    temperature_env_steps: list[int] = param([10_000, 20_000], "env steps at which the next temperature starts", ge=0)
    greedy_fraction: float = param(0.0, "share of each collector's envs that act greedily (temperature 0, root noise kept), "
                                         "so replay holds the states the greedy policy reaches (wmdist/algos/greedy_share.py; "
                                         "not in the MuZero paper); pUCT only",
                                   ge=0, le=1)
    temperature_moves: int = param(0, "board games: moves per episode at temperature 1 before playing greedily (0 = use the env-step schedule)", ge=0)

    def validate(self) -> "MuZeroConfig":
        if self.search.value_prefix and not self.has_value_prefix_net():
            raise ValueError("algo.search.value_prefix needs a network with a value-prefix head (LSTM); "
                             "muzero's has none (use algo.name: efficientzero)")
        if self.search.value_prefix and self.tree_model == "rules":
            raise ValueError("algo.search.value_prefix predicts rewards with a learned model; algo.tree_model=rules "
                             "takes them from the rules (set one of them)")
        if self.search.gumbel and self.greedy_fraction > 0:
            raise ValueError("algo.greedy_fraction has no effect with algo.search.gumbel (sequential halving chooses "
                             "every action); set one of them")
        if len(self.conv_downsample_blocks) != 3:
            raise ValueError(f"algo.conv_downsample_blocks needs 3 entries, got {self.conv_downsample_blocks}")
        if len(self.visit_temperatures) != len(self.temperature_env_steps) + 1:
            raise ValueError(
                f"algo.visit_temperatures needs one more entry than algo.temperature_env_steps, got "
                f"{len(self.visit_temperatures)} and {len(self.temperature_env_steps)}")
        if any(t < 0 for t in self.visit_temperatures):
            raise ValueError(f"algo.visit_temperatures must be >= 0, got {self.visit_temperatures}")
        if list(self.temperature_env_steps) != sorted(self.temperature_env_steps):
            raise ValueError(f"algo.temperature_env_steps must be increasing, got {self.temperature_env_steps}")
        if not self.hidden or any(int(w) < 1 for w in self.hidden):
            raise ValueError(f"algo.hidden must be a non-empty list of positive widths, got {self.hidden}")
        return self

    def has_value_prefix_net(self) -> bool:
        """Whether the network this config builds predicts value prefixes (EfficientZero's LSTM)."""
        return False
