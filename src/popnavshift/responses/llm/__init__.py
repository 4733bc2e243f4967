"""Network respondents: OpenAI-compatible servers and Gemini, behind a SQLite cache.

``OpenAIRespondent`` and ``GeminiRespondent`` share one engine
(:class:`~.transport.LLMRespondent`): content-addressed cache in front,
transport retries and content re-asks kept apart, a bounded thread pool and a
rate limiter. See ``docs/llm.md`` for usage.
"""

from .cache import CachedAnswer, CacheStats, ResponseCache, request_key
from .gemini import GeminiRespondent
from .openai import OpenAIRespondent
from .retries import RetryPolicy
from .transport import LLMRespondent

__all__ = [
    "CacheStats",
    "CachedAnswer",
    "GeminiRespondent",
    "LLMRespondent",
    "OpenAIRespondent",
    "ResponseCache",
    "RetryPolicy",
    "request_key",
]
