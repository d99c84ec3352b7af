"""A pure Monte Carlo tree search opponent: UCT (Kocsis & Szepesvari 2006) over the true
rules, each leaf valued by one uniformly random rollout to the end of the game.

Used where no exact solver exists (connect four): unlike a random player it punishes
blunders and blocks immediate threats, so an agent that beats it plays real moves.
A fixed number of rollouts per move and a seeded RNG make its strength and its games
reproducible.
"""
from __future__ import annotations

import math
import random

from wmdist.envs.boardgames.game import EMPTY, Game, State


class _Node:
    __slots__ = ("state", "parent", "children", "untried", "visits", "score")

    def __init__(self, game: Game, state: State, parent: "_Node | None", rng: random.Random) -> None:
        self.state, self.parent = state, parent
        self.children: dict[int, _Node] = {}
        self.untried = [int(a) for a in game.legal(state).nonzero()[0]]  # empty once the game is over
        rng.shuffle(self.untried)  # expansion order: random, so ties do not favour low actions
        self.visits = 0
        self.score = 0.0  # summed outcomes for the player who moved into this node (win 1, draw 0.5)


class MCTSOpponent:
    """UCT with random rollouts: `rollouts` simulations per move, then the most visited move.

    `exploration` is the UCB1 constant c in  score/n + c * sqrt(ln N / n)  (sqrt 2 for
    outcomes in [0, 1]).
    """

    def __init__(self, game: Game, rollouts: int = 200, seed: int = 0, exploration: float = math.sqrt(2)) -> None:
        if rollouts < 1:
            raise ValueError(f"rollouts must be >= 1, got {rollouts}")
        self.game, self.rollouts, self.c = game, int(rollouts), float(exploration)
        self._rng = random.Random(seed)

    def act(self, state: State) -> int:
        if self.game.terminal(state):
            raise ValueError("MCTSOpponent.act: the game is over, no legal move")
        root = _Node(self.game, state, None, self._rng)
        for _ in range(self.rollouts):
            node = self._select(root)
            if node.untried:
                node = self._expand(node)
            self._backup(node, self._rollout(node.state))
        most = max(child.visits for child in root.children.values())
        return self._rng.choice([a for a, child in root.children.items() if child.visits == most])

    __call__ = act  # usable directly as an `Opponent` (state -> action)

    def _select(self, node: _Node) -> _Node:
        """Descend through fully expanded nodes by UCB1 until a node with untried moves or a terminal."""
        while not node.untried and node.children:
            log_n = math.log(node.visits)
            node = max(node.children.values(),
                       key=lambda ch: ch.score / ch.visits + self.c * math.sqrt(log_n / ch.visits))
        return node

    def _expand(self, node: _Node) -> _Node:
        a = node.untried.pop()
        child = _Node(self.game, self.game.apply(node.state, a), node, self._rng)
        node.children[a] = child
        return child

    def _rollout(self, state: State) -> int | None:
        """Winner (0 or 1) of uniformly random play from `state`, or None for a draw."""
        g = self.game
        if g.terminal(state):
            return g.winner(state)
        # A mutable board and column heights: much faster than `Game.apply` per move.
        board, player, moves = list(state.board), state.to_play, state.moves
        rng = self._rng
        while moves < g.num_cells:
            if g.gravity:
                a = rng.choice([c for c in range(g.cols) if board[c] == EMPTY])
                cell = max(r for r in range(g.rows) if board[r * g.cols + a] == EMPTY) * g.cols + a
            else:
                cell = rng.choice([c for c in range(g.num_cells) if board[c] == EMPTY])
            board[cell] = player + 1
            moves += 1
            if g.completes_line(board, cell):
                return player
            player = 1 - player
        return None

    @staticmethod
    def _backup(node: _Node | None, winner: int | None) -> None:
        while node is not None:
            node.visits += 1
            mover = 1 - node.state.to_play  # the player whose move led to this node
            node.score += 0.5 if winner is None else float(winner == mover)
            node = node.parent
