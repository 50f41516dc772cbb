"""Spoken dialogue at the tables: Pepper takes the order by talking.

What a customer says (text, or WAV audio through the offline recogniser) becomes one
``Utterance`` fact per turn (:mod:`.words`, over the menu of :mod:`.menu`); the dialogue rule set
(``rules/drl/dialogue``) understands it, carries the conversation and answers, in one stateful
session per conversation (:mod:`.service`). The recogniser listens with a grammar made from the
rules' sentences and the menu (:mod:`.grammar`, :mod:`.speech`).
"""
