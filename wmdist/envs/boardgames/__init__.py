"""Two-player board games: rules (`game`), an exact tic-tac-toe solver, and the Env."""
from wmdist.envs.boardgames.env import BoardEnv
from wmdist.envs.boardgames.game import CONNECT4, GAMES, TICTACTOE, Game, IllegalMove, State
from wmdist.envs.boardgames.solver import SolverOpponent, action_values, best_actions, solve

__all__ = [
    "BoardEnv", "CONNECT4", "GAMES", "Game", "IllegalMove", "SolverOpponent", "State",
    "TICTACTOE", "action_values", "best_actions", "solve",
]
